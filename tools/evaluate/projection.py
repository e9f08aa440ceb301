"""Projected wall time of a suite on W workers, from the measured run times of one finished suite.

Sizing a cluster needs more than total run time / W: the suite has two phases, and its range searches
step outward one value at a time, so each search is a chain of runs that no number of workers shortens.
Phase 1 (the eta runs) is list-scheduled on W workers; phase 2 starts when it is done and runs every
chain at once, one run per chain in flight, as :func:`tools.evaluate.suite.run_suite` does.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Projection:
    workers: int
    eta_phase_s: float
    search_phase_s: float

    @property
    def wall_s(self) -> float:
        return self.eta_phase_s + self.search_phase_s


def split_runs(results: dict[str, Any]) -> tuple[list[float], list[list[float]]]:
    """(eta run times in run order, each range search's run times from its origin outward)."""
    summary = results["summary"]
    eta: list[float] = []
    chains: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for r in results["runs"]:
        entry = summary.get(r["experiment"], {})
        if entry.get("measure") in ("range", "max"):
            side = "lower" if r["value"] < entry["origin"] else "upper"
            chains.setdefault((r["experiment"], side), []).append((abs(r["value"] - entry["origin"]),
                                                                   r["wall_time_s"]))
        else:
            eta.append(r["wall_time_s"])
    return eta, [[t for _, t in sorted(c)] for c in chains.values()]


def _list_schedule(times: list[float], workers: int) -> float:
    free = [0.0] * workers
    for t in times:
        heapq.heappush(free, heapq.heappop(free) + t)
    return max(free)


def _chains(chains: list[list[float]], workers: int) -> float:
    ready, position, now = list(range(len(chains))), [0] * len(chains), 0.0
    busy: list[tuple[float, int]] = []  # a heap of (when the chain's running job ends, chain)
    while ready or busy:
        while ready and len(busy) < workers:
            c = ready.pop(0)
            heapq.heappush(busy, (now + chains[c][position[c]], c))
        now, c = heapq.heappop(busy)
        position[c] += 1
        if position[c] < len(chains[c]):
            ready.append(c)
    return now


def project(results: dict[str, Any], workers: int) -> Projection:
    """The suite of ``results`` (a results.json) replayed with its run times on ``workers`` workers."""
    eta, chains = split_runs(results)
    w = max(1, workers)
    return Projection(w, _list_schedule(eta, w) if eta else 0.0, _chains([c for c in chains if c], w))
