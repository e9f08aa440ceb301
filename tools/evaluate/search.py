"""Outward range search: step away from the origin until the first failure, within caps.

Steps are evaluated in speculative batches so that parallel workers stay busy, but the answer
is exactly that of stepping one at a time: the last passing value before the first failure.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field


@dataclass
class SearchResult:
    """Outcome of searching one direction."""

    limit: float | None  # last passing value (None: the first step already failed)
    first_failure: float | None  # None: no failure up to the cap
    hit_cap: bool
    tried: list[tuple[float, bool]] = field(default_factory=list)


def ladder(origin: float, step: float, cap: float) -> list[float]:
    """Values origin+step, origin+2*step, ... up to and including ``cap`` (direction from step's sign)."""
    if step == 0:
        raise ValueError("step must be non-zero")
    n = int((cap - origin) / step + 1e-9)
    return [round(origin + k * step, 10) for k in range(1, max(0, n) + 1)]


def step_outward(
    evaluate: Callable[[Sequence[float]], Sequence[bool]],
    origin: float,
    step: float,
    cap: float,
    batch: int = 1,
) -> SearchResult:
    """Step from ``origin`` towards ``cap``; ``evaluate`` answers pass/fail for a batch of values.

    The origin itself is assumed to pass (it is the no-variation run, judged by the caller).
    """
    values = ladder(origin, step, cap)
    result = SearchResult(limit=origin, first_failure=None, hit_cap=False)
    i = 0
    while i < len(values):
        chunk = values[i:i + max(1, batch)]
        outcomes = list(evaluate(chunk))
        if len(outcomes) != len(chunk):
            raise ValueError("evaluate must answer once per value")
        for value, ok in zip(chunk, outcomes, strict=True):
            result.tried.append((value, ok))
            if not ok:
                result.first_failure = value
                return result
            result.limit = value
        i += len(chunk)
    result.hit_cap = True
    return result
