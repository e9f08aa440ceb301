"""``rbc env-bench``: steps per second of ``rbc/Drive-v0`` on one core, and where a step's time goes.

The autopilot's action drives (``info["expert_action"]``), so the car stays on the road and the frames are the
ones an agent sees. Figures are the best of N runs, as wall-clock and as CPU-time rates and CPU milliseconds per
step (CPU time stays meaningful when other processes share the cores); OpenCV runs on the threads given (1:
per-core figures). Each row runs in a fresh process (:func:`bench_env_isolated`), so its peak resident memory is
one environment's: the interpreter, its imports and the world it builds.
"""

from __future__ import annotations

import cProfile
import io
import pstats
import resource
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from multiprocessing import get_context
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from tools.envs import DriveEnv


@dataclass(frozen=True)
class EnvBenchResult:
    track: str
    cameras: int
    jpeg: bool
    steps: int
    wall_steps_per_s: float
    cpu_steps_per_s: float
    resets: int  # episodes that ended inside the measurement (each reset's cost is included)
    observation: str = "frame"
    peak_rss_mb: float | None = None  # the measuring process's peak resident memory (None: not measured alone)

    @property
    def cpu_ms_per_step(self) -> float:
        return 1000.0 / self.cpu_steps_per_s

    def row(self) -> str:
        wire = "JPEG round trip" if self.jpeg else "rendered frame"
        if self.observation == "model":
            wire = "64x64 model input" if self.jpeg else "64x64, no JPEG"
        peak = "-" if self.peak_rss_mb is None else f"{self.peak_rss_mb:,.0f}"
        return (f"{self.track:<12} {self.cameras} camera{'s' if self.cameras > 1 else ' '}  {wire:<16} "
                f"{self.wall_steps_per_s:>8,.0f} {self.cpu_steps_per_s:>10,.0f} {self.cpu_ms_per_step:>7.3f} "
                f"{peak:>8}  {self.resets:>6}")


HEADER = (f"{'track':<12} {'cameras':<9} {'observation':<16} {'steps/s':>8} {'per CPU-s':>10} {'CPU ms':>7} "
          f"{'peak MB':>8}  {'resets':>6}")


def _drive(env, info: dict, steps: int) -> tuple[dict, int]:
    resets = 0
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(info["expert_action"])
        if terminated or truncated:
            _, info = env.reset()
            resets += 1
    return info, resets


def bench_env(track: str, cameras: int = 1, jpeg: bool = True, steps: int = 2000, repeats: int = 3,
              warmup: int = 200, seed: int = 0, observation: str = "frame", threads: int = 1) -> EnvBenchResult:
    """Steps per second of ``gymnasium.make("rbc/Drive-v0", track=track, ...)``: the best of ``repeats`` runs."""
    import gymnasium as gym

    import tools.envs  # noqa: F401  (registers rbc/Drive-v0)

    env = gym.make("rbc/Drive-v0", track=track, cameras=cameras, jpeg=jpeg, observation=observation,
                   threads=threads)
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
    return EnvBenchResult(track, cameras, jpeg, steps, max(wall), max(cpu), resets, observation)


def bench_env_isolated(track: str, cameras: int = 1, jpeg: bool = True, steps: int = 2000, repeats: int = 3,
                       warmup: int = 200, seed: int = 0, observation: str = "frame",
                       threads: int = 1) -> EnvBenchResult:
    """:func:`bench_env` in a fresh (spawned) process, with that process's peak resident memory: one environment's
    (the interpreter and its imports, the world it builds, the steps), not the worlds of the rows before."""
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        return pool.submit(_bench_env_measured, track, cameras, jpeg, steps, repeats, warmup, seed, observation,
                           threads).result()


def _bench_env_measured(track: str, cameras: int, jpeg: bool, steps: int, repeats: int, warmup: int, seed: int,
                        observation: str, threads: int) -> EnvBenchResult:
    result = bench_env(track, cameras, jpeg, steps, repeats, warmup, seed, observation, threads)
    return replace(result, peak_rss_mb=peak_rss_mb())


def peak_rss_mb() -> float:
    """This process's peak resident memory, MB (``getrusage``: kilobytes on Linux, bytes on macOS)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10


@dataclass(frozen=True)
class WorldsBenchResult:
    """The same episodes with their worlds built as they are drawn, or already built."""

    label: str
    episodes: int
    steps: int  # per episode
    wall_s: float  # per episode
    cpu_s: float  # per episode (the background thread's included)
    builds: int  # worlds built during the timed episodes
    waits: int  # resets that waited for a background build

    def row(self, base: WorldsBenchResult | None = None) -> str:
        extra = ""
        if base is not None:
            extra = f"{100 * (self.wall_s / base.wall_s - 1):>+7.1f} % {100 * (self.cpu_s / base.cpu_s - 1):>+7.1f} %"
        return f"{self.label:<30} {self.wall_s:>7.2f} {self.cpu_s:>7.2f} {self.builds:>6} {self.waits:>5}  {extra}"


WORLDS_HEADER = f"{'worlds':<30} {'wall s':>7} {'CPU s':>7} {'builds':>6} {'waits':>5}  {'wall':>9} {'CPU':>9}"


def bench_worlds(episodes: int = 6, steps: int = 1000, first_seed: int = 100, seed: int = 0, pool: int = 1,
                 new_world_steps: int = 1) -> list[WorldsBenchResult]:
    """Seconds per episode of ``steps`` autopilot steps from a random spawn, with ``worlds=`` drawing generated
    worlds (seeds from ``first_seed`` on; default: a new one every episode): built in the background while the
    episode before runs (prefetch), built at the reset, and already built (the same episodes again, every world
    in the cache: the baseline). Track files are generated, and the first pool built, before the clock starts."""
    import gymnasium as gym
    import numpy as np

    import tools.envs  # noqa: F401
    from tools.envs.rotation import WORLD_STREAM
    from tools.envs.worldcache import track_path
    from tools.envs.worlds import WorldDistribution

    dist = WorldDistribution(seeds=(first_seed, first_seed + 999), light=None, fog=None, pool=pool,
                             new_world_steps=new_world_steps)
    rng = np.random.default_rng([seed, WORLD_STREAM])
    for _ in range(pool + episodes + 2):  # the files of the worlds the episodes may draw (and a few more)
        track_path(dist.draw_world(rng)[0], dist.themes)
    results: list[WorldsBenchResult] = []
    for label, prefetch in (("built in the background", True), ("built at the reset", False)):
        env = gym.make("rbc/Drive-v0", spawn="random", max_episode_steps=steps, terminate_on_takeover=False,
                       worlds={**dist.__dict__, "prefetch": prefetch})
        drive = cast("DriveEnv", env.unwrapped)
        drive.worlds.clear()  # every world built afresh
        drive.worlds.size = max(drive.worlds.size, pool + episodes + 2)  # the second pass finds them all built
        try:
            for name in [label, "already built"] if prefetch else [label]:
                _, info = env.reset(seed=seed)
                for track, sun in drive.rotation.pool:  # the first pool: built before the clock starts
                    drive.worlds.get(drive.rotation.key(track, sun))
                drive.worlds.wait()
                builds0, waits0 = drive.worlds.builds, drive.worlds.waits
                t0, c0 = time.perf_counter(), time.process_time()
                for _ in range(episodes):
                    for _ in range(steps):
                        _, _, terminated, truncated, info = env.step(info["expert_action"])
                        if terminated or truncated:
                            break
                    _, info = env.reset()
                drive.worlds.wait()
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                results.append(WorldsBenchResult(name, episodes, steps, wall / episodes, cpu / episodes,
                                                 drive.worlds.builds - builds0, drive.worlds.waits - waits0))
        finally:
            env.close()
            drive.worlds.clear()
    return [results[1], results[0], results[2]]  # the baseline first


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
