"""Stable-Baselines3's PPO trains on rbc/Drive-v0 (the rl extra): a few thousand steps, a small network."""

from __future__ import annotations

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")
sb3 = pytest.importorskip("stable_baselines3",
                          reason="stable_baselines3 is not installed: PPO on rbc/Drive-v0 needs pip install -e '.[rl]'")
torch = pytest.importorskip("torch", reason="stable_baselines3 needs torch")

import tools.envs  # noqa: E402,F401  (registers rbc/Drive-v0)


@pytest.mark.slow
def test_ppo_trains_a_few_thousand_steps_on_downsampled_frames():
    from gymnasium.wrappers import ResizeObservation
    from stable_baselines3 import PPO

    torch.set_num_threads(1)  # the machine's other core is someone else's
    env = ResizeObservation(gym.make("rbc/Drive-v0", track="lake", jpeg=False, spawn="random"), (40, 80))
    model = PPO("CnnPolicy", env, n_steps=512, batch_size=128, n_epochs=2, seed=0, device="cpu",
                policy_kwargs={"features_extractor_kwargs": {"features_dim": 64}, "net_arch": [32]})
    model.learn(total_timesteps=2048)
    assert model.num_timesteps >= 2048
    obs, _ = env.reset(seed=1)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(np.asarray(action, np.float32))
    _, reward, *_ = env.step(action)
    assert np.isfinite(reward)
    env.close()


@pytest.mark.slow
def test_the_ppo_recipe_trains_saves_and_draws_its_curve(tmp_path, capsys):
    """tools.envs.ppo (the Python page's PPO recipe): a few hundred steps of the small CNN on the 64x64 input."""
    from stable_baselines3 import PPO

    from tools.envs.ppo import PPORecipe, read_monitor, small_cnn, train_ppo

    torch.set_num_threads(1)
    recipe = PPORecipe(timesteps=256, envs=1, n_steps=128, batch_size=64, n_epochs=1, max_episode_steps=60)
    path = train_ppo(recipe, tmp_path)
    model = PPO.load(path, device="cpu")
    assert model.num_timesteps >= 256
    assert isinstance(model.policy.features_extractor, small_cnn())
    weights = sum(p.numel() for p in model.policy.features_extractor.parameters())
    assert weights < 60_000  # a small CNN, not the 19M-weight CnnPolicy of full frames
    episodes = read_monitor(tmp_path / "monitor.csv")
    assert len(episodes) >= 4 and all(length <= 256 for length, _ in episodes)
    assert (tmp_path / "recipe.json").is_file()
    pytest.importorskip("matplotlib")
    assert (tmp_path / "curve.png").stat().st_size > 5_000
    from tools.envs.ppo import evaluate_ppo

    rows = evaluate_ppo(path, ("lake", "world:1000000"), max_steps=30)  # an evaluation world: purpose="eval"
    assert [r["track"] for r in rows] == ["lake", "world:1000000"]
    assert all(r["steps"] <= 30 and r["metres"] >= 0 and not r["lap"] for r in rows)
