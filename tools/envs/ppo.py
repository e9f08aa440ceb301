"""A PPO recipe for ``rbc/Drive-v0``: Stable-Baselines3's PPO with a small CNN on the network's own 64x64 input.

``python -m tools.envs.ppo --out runs/ppo`` (the ``rl`` extra) trains from scratch on the lake from random
spawns: the observation is the model's 64x64 input and the speed (``observation="model", speed=True``), the
action the steering with the paper's coupled throttle (``control="steer"``), the reward the default (metres
along the lap, about 1,003 a lap). The policy starts with a narrow spread (``log_std_init=-1``): with the
coupled throttle, wide steering crawls. ``--worlds`` trains on generated worlds instead (a new one every few
episodes). It writes ``OUT/model.zip`` (SB3's), ``OUT/monitor.csv`` (every episode's return, length and time),
``OUT/recipe.json`` and, with matplotlib, ``OUT/curve.png`` (the episodes' return against the steps).
"""

from __future__ import annotations

import argparse
import functools
import json
import logging
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from tools.envs.policy import Observation

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PPORecipe:
    track: str = "lake"
    worlds: dict[str, object] | None = None  # a WorldDistribution's fields: generated worlds instead of the track
    timesteps: int = 200_000
    envs: int = 2  # environments stepped in parallel (one process each when more than one)
    max_episode_steps: int = 1000  # 67 simulated seconds
    n_steps: int = 512  # per environment and update
    batch_size: int = 128
    n_epochs: int = 4
    learning_rate: float = 3e-4
    gamma: float = 0.99
    log_std_init: float = -1.0
    features: int = 64
    seed: int = 0
    env_kwargs: dict[str, object] = field(default_factory=dict)  # any other rbc/Drive-v0 keyword

    def make_kwargs(self) -> dict[str, Any]:  # gymnasium.make's keywords, each of its own type
        """The keywords of each ``gymnasium.make("rbc/Drive-v0", ...)``."""
        world: dict[str, object] = {"worlds": self.worlds} if self.worlds is not None else {"track": self.track}
        return {**world, "observation": "model", "speed": True, "spawn": "random",
                "max_episode_steps": self.max_episode_steps, **self.env_kwargs}


@functools.cache
def small_cnn() -> type:
    """The features extractor: three convolutions on the 64x64 image (48,000 weights) to ``features``
    numbers, with the speed (km/h / 25) beside them."""
    import torch
    from gymnasium import spaces
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    class SmallCNN(BaseFeaturesExtractor):
        def __init__(self, observation_space: spaces.Dict, features: int = 64) -> None:
            super().__init__(observation_space, features + 1)
            image = observation_space["center"]
            assert image.shape is not None
            channels = image.shape[0]  # SB3 hands images channels first
            self.cnn = torch.nn.Sequential(
                torch.nn.Conv2d(channels, 16, 5, stride=2), torch.nn.ReLU(),
                torch.nn.Conv2d(16, 32, 3, stride=2), torch.nn.ReLU(),
                torch.nn.Conv2d(32, 32, 3, stride=2), torch.nn.ReLU(),
                torch.nn.AdaptiveAvgPool2d(4), torch.nn.Flatten())
            self.head = torch.nn.Sequential(torch.nn.Linear(32 * 16, features), torch.nn.ReLU())

        def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
            image = self.head(self.cnn(obs["center"]))  # SB3 scaled the uint8 image to 0..1
            return torch.cat([image, obs["speed"] / 25.0], dim=1)

    return SmallCNN


def train_ppo(recipe: PPORecipe, out: str | Path, progress: bool = False) -> Path:
    """Train; returns the saved model's path (``OUT/model.zip``)."""
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor

    import tools.envs  # noqa: F401  (registers rbc/Drive-v0)

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "recipe.json").write_text(json.dumps(asdict(recipe), indent=2) + "\n", encoding="utf-8")
    kwargs = recipe.make_kwargs()

    def make() -> gym.Env[Observation, np.ndarray]:
        return gym.make("rbc/Drive-v0", **kwargs)

    if recipe.envs > 1 and recipe.worlds is None:
        make().close()  # the track's world built here, once: the forked workers share it (read-only pages)
    envs = SubprocVecEnv([make] * recipe.envs, start_method="fork") if recipe.envs > 1 else DummyVecEnv([make])
    if isinstance(envs, SubprocVecEnv):
        from tools.envs.affinity import pin_workers

        pin_workers(envs)  # each worker keeps a core and its caches (the same episodes: placement is not a draw)
    vec = VecMonitor(envs, str(out / "monitor.csv"))
    vec.seed(recipe.seed)
    model = PPO("MultiInputPolicy", vec, n_steps=recipe.n_steps, batch_size=recipe.batch_size,
                n_epochs=recipe.n_epochs, learning_rate=recipe.learning_rate, gamma=recipe.gamma,
                seed=recipe.seed, device="cpu", verbose=0,
                policy_kwargs={"features_extractor_class": small_cnn(),
                               "features_extractor_kwargs": {"features": recipe.features},
                               "net_arch": [64], "log_std_init": recipe.log_std_init})
    try:
        model.learn(total_timesteps=recipe.timesteps, progress_bar=progress)
    finally:
        vec.close()
    path = out / "model.zip"
    model.save(path)
    plot_curve(out / "monitor.csv", out / "curve.png")
    return path


def read_monitor(path: Path) -> list[tuple[int, float]]:
    """(steps so far, the episode's return) of every episode of an SB3 monitor file."""
    import csv

    rows, steps = [], 0
    with path.open(encoding="utf-8") as fh:
        next(fh)  # SB3's JSON header line
        for row in csv.DictReader(fh):
            steps += int(row["l"])
            rows.append((steps, float(row["r"])))
    return rows


def plot_curve(monitor: Path, picture: Path) -> Path | None:
    """The learning curve (each episode's return and a running mean of 20 against the steps), if matplotlib is
    installed and there was an episode."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ModuleNotFoundError:
        return None
    episodes = read_monitor(monitor)
    if not episodes:
        return None
    steps, returns = zip(*episodes, strict=True)
    mean = [sum(returns[max(0, i - 19):i + 1]) / len(returns[max(0, i - 19):i + 1]) for i in range(len(returns))]
    fig, ax = plt.subplots(figsize=(7, 3.5), dpi=100)
    ax.plot(steps, returns, ".", ms=2, alpha=0.4, label="episode")
    ax.plot(steps, mean, label="mean of 20")
    ax.set_xlabel("steps")
    ax.set_ylabel("return (m along the lap)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(picture)
    plt.close(fig)
    return picture


#: Where a trained policy is driven once from the start: the track it learnt and five evaluation worlds.
EVAL_TRACKS = ("lake", "mountain", *(f"world:{1_000_000 + k}" for k in range(5)))


def evaluate_ppo(model: str | Path, tracks: tuple[str, ...] = EVAL_TRACKS, max_steps: int = 6000) -> list[dict]:
    """Each track driven once from its start by the policy (its mean action): the metres driven before the
    first take-over (the episode ends there), whether the lap was driven, and the take-over's cause."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    import tools.envs  # noqa: F401  (registers rbc/Drive-v0)

    policy = PPO.load(str(model), device="cpu")
    rows = []
    for track in tracks:
        env = gym.make("rbc/Drive-v0", track=track, observation="model", speed=True, max_episode_steps=max_steps,
                       purpose="eval")
        try:
            obs, info = env.reset(seed=0)
            done = False
            while not done:
                action, _ = policy.predict(obs, deterministic=True)
                obs, _, terminated, truncated, info = env.step(action)
                done = terminated or truncated
        finally:
            env.close()
        rows.append({"track": track, "metres": round(float(info["progress_m"]), 1), "lap": bool(info["laps_done"]),
                     "takeover": info["intervention"] or "", "steps": int(info["step"])})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tools.envs.ppo", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="folder for model.zip, monitor.csv, recipe.json, curve.png")
    parser.add_argument("--timesteps", type=int, default=PPORecipe.timesteps)
    parser.add_argument("--envs", type=int, default=PPORecipe.envs)
    parser.add_argument("--track", default=PPORecipe.track)
    parser.add_argument("--worlds", action="store_true", help="generated training worlds (worlds=True)")
    parser.add_argument("--seed", type=int, default=PPORecipe.seed)
    parser.add_argument("--evaluate", action="store_true",
                        help="do not train: drive OUT/model.zip once from the start of the lake, the mountain and five "
                             "evaluation worlds and write OUT/evaluation.json")
    args = parser.parse_args(argv)
    if args.evaluate:
        rows = evaluate_ppo(Path(args.out) / "model.zip")
        (Path(args.out) / "evaluation.json").write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
        for row in rows:
            print(f"{row['track']:>16}: {row['metres']:7.1f} m, " + ("lap driven" if row["lap"] else
                  f"take-over: {row['takeover'] or 'none (time up)'}"))
        return 0
    if args.timesteps < 1 or args.envs < 1:
        parser.error("--timesteps and --envs must be >= 1")
    recipe = PPORecipe(track=args.track, worlds={} if args.worlds else None, timesteps=args.timesteps,
                       envs=args.envs, seed=args.seed)
    path = train_ppo(recipe, args.out, progress=False)
    episodes = read_monitor(Path(args.out) / "monitor.csv")
    last = [r for _, r in episodes[-20:]]
    print(f"{recipe.timesteps} steps, {len(episodes)} episodes; mean return of the last {len(last)}: "
          f"{sum(last) / max(1, len(last)):.1f}; {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
