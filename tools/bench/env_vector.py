"""``rbc env-bench --vector N``: ``rbc/Drive-v0`` in a Gymnasium ``AsyncVectorEnv`` of N processes against one env.

Wall-clock scaling (the vector env's steps per second over one env's) is what a trainer gets, but on shared cores
it measures the other jobs as much as the env; the CPU time of each process is what contention disturbs least:
each worker's CPU milliseconds per step (against one env's in the same run), the main process's per vector step
(Gymnasium's own work: sending the actions, reading the observations and merging the infos, done while the
workers wait, so it bounds the scaling: ``N * one / (worker + main)`` at best), and each worker's peak resident
memory and proportional share (PSS: pages shared with the parent and the other workers, the world the parent
built before they were forked, counted once across them). Everything runs in a fresh (spawned) process, whose
workers are forked from it (Gymnasium's default on Linux); the one env is timed after the vector env, in the same
process. Worker figures come from ``/proc`` (Linux; elsewhere they are left out).
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_all_start_methods, get_context
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gymnasium.vector import AsyncVectorEnv


@dataclass(frozen=True)
class VectorTiming:
    """The vector env's wall-clock rate and each process's CPU time, for one way of placing the workers."""

    steps_per_s: float  # env steps per second, wall clock
    worker_cpu_ms: tuple[float, ...]  # each worker's CPU ms per env step
    main_cpu_ms: float  # the main process's CPU ms per vector step


@dataclass(frozen=True)
class VectorBenchResult:
    envs: int
    steps: int  # vector steps timed (each is ``envs`` env steps)
    one_steps_per_s: float  # one env in the process, wall clock
    one_cpu_ms: float  # one env's CPU ms per step
    vector_steps_per_s: float  # env steps per second of the vector env, wall clock
    worker_cpu_ms: tuple[float, ...]  # each worker's CPU ms per env step
    main_cpu_ms: float  # the main process's CPU ms per vector step
    worker_peak_rss_mb: tuple[float, ...]
    worker_pss_mb: tuple[float, ...]  # each worker's proportional share of memory at the end
    main_pss_mb: tuple[float, ...]  # the main process's (empty where it cannot be read)
    pinned: VectorTiming | None = None  # the same workers then pinned to a CPU each (tools.envs.pin_workers)

    @property
    def scaling(self) -> float:
        return self.vector_steps_per_s / self.one_steps_per_s

    @property
    def cpu_bound(self) -> float:
        """The scaling the CPU times allow with a core per process: N one-env steps in the time of the slowest
        worker's step plus the main process's share, which runs while the workers wait."""
        if not self.worker_cpu_ms:
            return float("nan")
        return self.envs * self.one_cpu_ms / (max(self.worker_cpu_ms) + self.main_cpu_ms)

    def lines(self) -> list[str]:
        def ms(values: tuple[float, ...]) -> str:
            return ", ".join(f"{v:.3f}" for v in values) or "-"

        def mb(values: tuple[float, ...]) -> str:
            return ", ".join(f"{v:,.0f}" for v in values) or "-"

        lines = [
            f"one env:              {self.one_steps_per_s:>8,.0f} steps/s wall, {self.one_cpu_ms:.3f} CPU ms/step",
            f"AsyncVectorEnv x{self.envs}:   {self.vector_steps_per_s:>8,.0f} env steps/s wall "
            f"({self.scaling:.2f}x one env); CPU ms per env step by worker: {ms(self.worker_cpu_ms)}; "
            f"main process {self.main_cpu_ms:.3f} CPU ms per vector step (the CPU times allow "
            f"{self.cpu_bound:.2f}x)",
        ]
        if self.pinned is not None:
            p = self.pinned
            lines.append(f"  workers pinned:     {p.steps_per_s:>8,.0f} env steps/s wall "
                         f"({p.steps_per_s / self.one_steps_per_s:.2f}x one env; tools.envs.pin_workers); CPU ms "
                         f"per env step by worker: {ms(p.worker_cpu_ms)}; main process {p.main_cpu_ms:.3f}")
        lines.append(f"memory by worker:     peak RSS {mb(self.worker_peak_rss_mb)} MB, PSS "
                     f"{mb(self.worker_pss_mb)} MB (main process PSS {mb(self.main_pss_mb)} MB)")
        return lines


def bench_vector(track: str = "lake", envs: int = 2, steps: int = 2000, warmup: int = 100, seed: int = 0,
                 observation: str = "frame") -> VectorBenchResult:
    """An ``AsyncVectorEnv`` of ``envs`` envs, then one env, ``steps`` steps each, in a fresh process."""
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        return pool.submit(_bench_vector, track, envs, steps, warmup, seed, observation).result()


def _bench_vector(track: str, envs: int, steps: int, warmup: int, seed: int, observation: str) -> VectorBenchResult:
    import gymnasium as gym
    import numpy as np

    import tools.envs  # noqa: F401  (registers rbc/Drive-v0)
    from tools.envs.affinity import pin_workers

    def make() -> gym.Env[np.ndarray, np.ndarray]:  # the module path: a spawned worker imports and registers it
        return gym.make("tools.envs:rbc/Drive-v0", track=track, observation=observation)

    # forked as Gymnasium does by default on Linux (this process was spawned, which would make spawn the default)
    context = "fork" if "fork" in get_all_start_methods() else None
    vec = gym.vector.AsyncVectorEnv([make] * envs, context=context)  # resets itself on episode ends (the next step)
    try:
        _, infos = vec.reset(seed=seed)
        for _ in range(warmup):
            _, _, _, _, infos = vec.step(infos["expert_action"])
        pids = [process.pid for process in vec.processes]
        free, infos = _time_vector(vec, infos, pids, steps)
        pinned = None
        if pin_workers(vec):
            for _ in range(warmup):  # the workers settle on their CPUs
                _, _, _, _, infos = vec.step(infos["expert_action"])
            pinned, infos = _time_vector(vec, infos, pids, steps)
        peaks = tuple(v for v in (_status_mb(pid, "VmHWM") for pid in pids) if v is not None)
        pss = tuple(v for v in (_pss_mb(pid) for pid in [*pids, os.getpid()]) if v is not None)
    finally:
        vec.close()

    one = make()  # after the vector env: the workers were forked from a process that had made only its first env
    _, info = one.reset(seed=seed)
    for _ in range(warmup):
        _, _, terminated, truncated, info = one.step(info["expert_action"])
        if terminated or truncated:
            _, info = one.reset()
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        _, _, terminated, truncated, info = one.step(info["expert_action"])
        if terminated or truncated:
            _, info = one.reset()
    one_wall, one_cpu = time.perf_counter() - t0, time.process_time() - c0
    one.close()
    return VectorBenchResult(envs, steps, steps / one_wall, 1000.0 * one_cpu / steps, free.steps_per_s,
                             free.worker_cpu_ms, free.main_cpu_ms, peaks, pss[:len(pids)], pss[len(pids):], pinned)


def _time_vector(vec: AsyncVectorEnv, infos: dict, pids: list[int | None], steps: int) -> tuple[VectorTiming, dict]:
    """``steps`` vector steps of ``vec``, the autopilot driving: its timing, and the last infos."""
    w0 = [_cpu_s(pid) for pid in pids]
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(steps):
        _, _, _, _, infos = vec.step(infos["expert_action"])
    wall, main_cpu = time.perf_counter() - t0, time.process_time() - c0
    worker_cpu = tuple(1000.0 * (end - start) / steps for start, end in zip(w0, map(_cpu_s, pids), strict=True)
                       if start is not None and end is not None)
    return VectorTiming(len(pids) * steps / wall, worker_cpu, 1000.0 * main_cpu / steps), infos


def _cpu_s(pid: int | None) -> float | None:
    """A process's user and system CPU seconds (``/proc/PID/stat``), None where it cannot be read."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _status_mb(pid: int | None, key: str) -> float | None:
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except OSError:
        return None
    return next((int(line.split()[1]) / 1024 for line in lines if line.startswith(key + ":")), None)


def _pss_mb(pid: int | None) -> float | None:
    try:
        lines = Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines()
    except OSError:
        return None
    return next((int(line.split()[1]) / 1024 for line in lines if line.startswith("Pss:")), None)
