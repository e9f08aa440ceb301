"""The centre line's geometry: a C2 periodic cubic spline through the control points, resampled.

C2 so that curvature is continuous and a vehicle can follow it; resampled every ~0.5 m so every
query of the simulator is an array lookup.
"""

from __future__ import annotations

import numpy as np

SAMPLE_SPACING = 0.5  # metres between resampled centre-line points

def _periodic_spline(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Chord-length knots and second derivatives of the C2 periodic cubic spline through ``pts``."""
    n = len(pts)
    h = np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)  # h[i]: knot i -> i+1
    hp = np.roll(h, 1)  # h[i-1]
    a = np.zeros((n, n))
    idx = np.arange(n)
    a[idx, (idx - 1) % n] += hp
    a[idx, idx] += 2 * (hp + h)
    a[idx, (idx + 1) % n] += h
    slope = (np.roll(pts, -1, 0) - pts) / h[:, None]
    rhs = 6 * (slope - np.roll(slope, 1, 0))
    m = np.linalg.solve(a, rhs)
    return h, m


def _eval_spline(pts: np.ndarray, h: np.ndarray, m: np.ndarray, t: np.ndarray):
    """Position, first and second derivative at global parameters ``t`` in [0, sum(h))."""
    knots = np.concatenate([[0.0], np.cumsum(h)])
    i = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(h) - 1)
    hi = h[i][:, None]
    u = (t - knots[i])[:, None]
    v = hi - u
    p0, p1 = pts[i], pts[(i + 1) % len(pts)]
    m0, m1 = m[i], m[(i + 1) % len(pts)]
    pos = m0 * v**3 / (6 * hi) + m1 * u**3 / (6 * hi) + (p0 / hi - m0 * hi / 6) * v + (p1 / hi - m1 * hi / 6) * u
    d1 = -m0 * v**2 / (2 * hi) + m1 * u**2 / (2 * hi) - (p0 / hi - m0 * hi / 6) + (p1 / hi - m1 * hi / 6)
    d2 = m0 * v / hi + m1 * u / hi
    return pos, d1, d2


def resample_loop(control: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Resample the smoothed loop every ~SAMPLE_SPACING metres; return points, tangents, curvature, length."""
    h, m = _periodic_spline(control)
    total = float(h.sum())
    dense_t = np.linspace(0.0, total, max(int(total / 0.05), 400), endpoint=False)
    pos, _, _ = _eval_spline(control, h, m, dense_t)
    seg = np.linalg.norm(np.roll(pos, -1, 0) - pos, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    length = float(cum[-1])
    n = max(int(round(length / SAMPLE_SPACING)), 8)
    target = np.arange(n) * (length / n)
    t = np.interp(target, cum, np.concatenate([dense_t, [total]]))
    pts, d1, d2 = _eval_spline(control, h, m, t)
    speed = np.linalg.norm(d1, axis=1)
    tan = d1 / speed[:, None]
    curv = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / speed**3
    return pts, tan, curv, length
