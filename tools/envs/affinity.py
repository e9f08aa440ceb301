"""Each worker process of a vector env on a CPU of its own.

A vector env's workers sleep while the main process gathers their steps and wake when it sends the next actions;
left to the scheduler, a worker often wakes on the other core, away from its caches, and its step costs more CPU.
Measured with ``rbc env-bench --vector 2`` on the project's two cores (an ``AsyncVectorEnv`` of 2 on the lake, the
JPEG round trip, in runs an hour apart): free, each worker spent 1.32-1.46 CPU ms a step against one env's
1.06-1.17 alone, and the pair ran at 0.9-1.2x one env's wall-clock rate; pinned, at 1.4-1.5x. The PPO recipe's
200,000 steps took 10.1 minutes free and 8.6 pinned. The main process is left free: it works while the workers
wait.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from typing import Protocol

log = logging.getLogger(__name__)


class _Process(Protocol):
    @property
    def pid(self) -> int | None: ...


class VectorWithProcesses(Protocol):
    """Gymnasium's ``AsyncVectorEnv`` and Stable-Baselines3's ``SubprocVecEnv`` both keep their workers here."""

    @property
    def processes(self) -> Sequence[_Process]: ...


def pin_workers(vec: VectorWithProcesses, cpus: Sequence[int] | None = None) -> dict[int, int]:
    """Pin worker ``i`` of ``vec`` to ``cpus[i % len(cpus)]`` (default: the CPUs this process may use, in order).

    Returns ``{pid: cpu}`` of the workers pinned; ``{}`` where the system has no CPU affinity (macOS, Windows),
    which leaves the workers to the scheduler as before. Call it after making the vector env, before stepping::

        vec = gym.make_vec("tools.envs:rbc/Drive-v0", num_envs=2, vectorization_mode="async", track="lake")
        pin_workers(vec.unwrapped)  # a wrapped vector env: its AsyncVectorEnv
    """
    if not hasattr(os, "sched_setaffinity"):
        return {}
    choice = sorted(os.sched_getaffinity(0)) if cpus is None else list(cpus)
    if not choice:
        raise ValueError("pin_workers: no CPUs to pin the workers to")
    pinned: dict[int, int] = {}
    for i, process in enumerate(vec.processes):
        pid, cpu = process.pid, choice[i % len(choice)]
        if pid is None:  # not started
            continue
        try:
            os.sched_setaffinity(pid, {cpu})
        except (ProcessLookupError, PermissionError) as exc:  # a worker that ended, or is not ours to pin
            log.warning("pin_workers: worker %d (pid %d) left to the scheduler: %s", i, pid, exc)
            continue
        pinned[pid] = cpu
    return pinned
