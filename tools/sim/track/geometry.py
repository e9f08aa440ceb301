"""Where a closed centre line comes too near itself: the one check the track loader and the world
generator share (a road must not overlap another stretch of itself).

Pairs of points further apart along the line than pi/2 * clearance must be at least ``clearance``
apart in space; with curve radii >= clearance / 2 closer pairs are always far enough apart. Squared
distances come from one matrix product per block (|a|^2 + |b|^2 - 2 a.b), several times faster
than differencing every pair, which matters for a generator that checks many candidate loops.
"""

from __future__ import annotations

import math

import numpy as np

BLOCK = 1024


def closest_overlap(p: np.ndarray, along: np.ndarray, length: float,
                    clearance: float) -> tuple[int, int, float] | None:
    """(i, j, distance) of the closest pair of points ``p`` (n, 2) that breaks the rule, or None.

    ``along`` is each point's arc length on a loop of ``length`` metres.
    """
    gap = math.pi / 2 * clearance
    c = p - p.mean(0)  # small coordinates keep the product trick accurate
    sq = (c * c).sum(1)
    limit = (clearance - 1e-6) ** 2
    best = None
    for lo in range(0, len(c), BLOCK):
        blk = c[lo:lo + BLOCK]
        d2 = sq[lo:lo + BLOCK, None] + sq[None] - 2.0 * (blk @ c.T)
        sep = np.abs(along[lo:lo + BLOCK, None] - along[None])
        bad = (np.minimum(sep, length - sep) > gap) & (d2 < limit)
        if bad.any():
            k = int(np.argmin(np.where(bad, d2, np.inf)))
            i, j = divmod(k, len(c))
            d = math.sqrt(max(float(d2[i, j]), 0.0))
            if best is None or d < best[2]:
                best = (i + lo, j, d)
    return best
