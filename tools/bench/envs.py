"""``rbc env-bench``: steps per second of ``rbc/Drive-v0`` on one core, and where a step's time goes.

The autopilot's action drives (``info["expert_action"]``), so the car stays on the road and the frames are the
ones an agent sees. Figures are the best of N runs, as wall-clock and as CPU-time rates (the latter stays
meaningful when other processes share the cores); OpenCV runs on the threads given (1: per-core figures).
"""

from __future__ import annotations

import cProfile
import io
import pstats
import time
from dataclasses import dataclass


@dataclass(frozen=True)
class EnvBenchResult:
    track: str
    cameras: int
    jpeg: bool
    steps: int
    wall_steps_per_s: float
    cpu_steps_per_s: float
    resets: int  # episodes that ended inside the measurement (each reset's cost is included)

    def row(self) -> str:
        wire = "JPEG round trip" if self.jpeg else "rendered frame"
        return (f"{self.track:<12} {self.cameras} camera{'s' if self.cameras > 1 else ' '}  {wire:<16} "
                f"{self.wall_steps_per_s:>8,.0f} {self.cpu_steps_per_s:>10,.0f}  {self.resets:>6}")


HEADER = f"{'track':<12} {'cameras':<9} {'observation':<16} {'steps/s':>8} {'per CPU-s':>10}  {'resets':>6}"


def _drive(env, info: dict, steps: int) -> tuple[dict, int]:
    resets = 0
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(info["expert_action"])
        if terminated or truncated:
            _, info = env.reset()
            resets += 1
    return info, resets


def bench_env(track: str, cameras: int = 1, jpeg: bool = True, steps: int = 2000, repeats: int = 3,
              warmup: int = 200, seed: int = 0) -> EnvBenchResult:
    """Steps per second of ``gymnasium.make("rbc/Drive-v0", track=track, ...)``: the best of ``repeats`` runs."""
    import gymnasium as gym

    import tools.envs  # noqa: F401  (registers rbc/Drive-v0)

    env = gym.make("rbc/Drive-v0", track=track, cameras=cameras, jpeg=jpeg)
    try:
        _, info = env.reset(seed=seed)
        info, _ = _drive(env, info, warmup)  # world textures, caches, first touches of memory
        wall, cpu, resets = [], [], 0
        for _ in range(max(1, repeats)):
            t0, c0 = time.perf_counter(), time.process_time()
            info, n = _drive(env, info, steps)
            wall.append(steps / (time.perf_counter() - t0))
            cpu.append(steps / max(time.process_time() - c0, 1e-9))
            resets += n
    finally:
        env.close()
    return EnvBenchResult(track, cameras, jpeg, steps, max(wall), max(cpu), resets)


def profile_env(track: str, steps: int, jpeg: bool = True, top: int = 15, seed: int = 0) -> str:
    """cProfile of ``steps`` steps on ``track`` (one camera): the functions with the most time of their own."""
    import gymnasium as gym

    import tools.envs  # noqa: F401

    env = gym.make("rbc/Drive-v0", track=track, jpeg=jpeg)
    try:
        _, info = env.reset(seed=seed)
        info, _ = _drive(env, info, 200)
        profiler = cProfile.Profile()
        profiler.enable()
        _drive(env, info, steps)
        profiler.disable()
    finally:
        env.close()
    out = io.StringIO()
    pstats.Stats(profiler, stream=out).sort_stats("tottime").print_stats(top)
    return out.getvalue()
