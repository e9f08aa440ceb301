"""Closed centre lines from a random sequence of corners, straights and S-bend chains.

Why not perturbed polar points: their curvature is uncontrolled, so hairpins at the car's limit and
long straights are rare. Here the road is built as a curvature profile -- arcs of chosen radius
and angle, straights, zero-net S-chains -- whose corner angles sum to one full turn, smoothed so
curvature ramps in and out (the spline through it stays C2 without overshoot). The loop is then
closed exactly by lengthening or shortening the straights (the minimum-norm change that cancels
the end gap), and rejected if it comes near itself; rejection draws again from the same seeded
generator, so a seed always gives the same road.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tools.sim.track.geometry import closest_overlap
from tools.sim.worldgen.config import WorldGenConfig

DS = 0.5  # metres per sample of the curvature profile
RAMP_M = 6.0  # box-filter width (applied twice): curvature ramps over about 2 x this
MIN_STRAIGHT_M = 8.0
CONTROL_SPACING_M = 4.0  # control points written to the track file


@dataclass(frozen=True)
class Layout:
    points: np.ndarray  # (n, 2) centre line every DS metres, closed (first point not repeated)
    curvature: np.ndarray  # (n,) 1/m of the profile (before the spline)
    start_s: float  # middle of the longest straight
    features: dict[str, int]  # counts of corner kinds, for the description


def _pieces(rng: np.random.Generator, cfg: WorldGenConfig, hairpin_r: float) -> tuple[list, dict] | None:
    """(length, curvature, is_straight) pieces whose turning sums to one full turn, or None."""
    n = int(rng.integers(4, 10))
    kinds = rng.choice(["sweeper", "corner", "hairpin"], n, p=[0.4, 0.42, 0.18])
    corners = []
    for kind in kinds:
        if kind == "sweeper":
            corners.append([float(rng.uniform(25, 100)), float(rng.uniform(40, 150))])
        elif kind == "corner":
            corners.append([float(rng.uniform(40, 120)), float(rng.uniform(max(12.0, hairpin_r), 40))])
        else:
            corners.append([float(rng.uniform(150, 185)), float(rng.uniform(hairpin_r, hairpin_r + 5))])
    sign = np.where(rng.uniform(0, 1, n) < 0.28, -1.0, 1.0)
    sign[int(np.argmax([c[0] for c in corners]))] = 1.0
    neg = sum(c[0] for c, s in zip(corners, sign, strict=True) if s < 0)
    pos = sum(c[0] for c, s in zip(corners, sign, strict=True) if s > 0)
    scale = (360.0 + neg) / pos
    for c, s in zip(corners, sign, strict=True):
        if s > 0:
            c[0] *= scale
        if not 15.0 <= c[0] <= 200.0:
            return None
    pieces = []
    for (angle, radius), s in zip(corners, sign, strict=True):
        pieces.append((radius * math.radians(angle), s / radius, False))
        pieces.append((float(rng.uniform(15, 120)), 0.0, True))
        if rng.uniform() < 0.3:  # a chain of S-bends with no net turn, then another straight
            k = int(rng.integers(2, 5))
            a, r = math.radians(rng.uniform(20, 55)), float(rng.uniform(max(15.0, hairpin_r), 45))
            turns = [a] + [-2 * a if i % 2 else 2 * a for i in range(1, k - 1)] + [a if k % 2 else -a]
            first = 1.0 if rng.uniform() < 0.5 else -1.0
            pieces += [(r * abs(t), first * math.copysign(1.0, t) / r, False) for t in turns]
            pieces.append((float(rng.uniform(10, 80)), 0.0, True))
    feats = {"sweepers": int((kinds == "sweeper").sum()), "corners": int((kinds == "corner").sum()),
             "hairpins": int((kinds == "hairpin").sum()), "counter_turns": int((sign < 0).sum())}
    return pieces, feats


def _profile(pieces: list) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Smoothed curvature per DS sample, scaled to one full turn; sample ranges of the straights."""
    kappa: list[float] = []
    straights: list[tuple[int, int]] = []
    for length, k, straight in pieces:
        m = max(1, int(round(length / DS)))
        if straight:
            straights.append((len(kappa), len(kappa) + m))
        kappa += [k] * m
    kap = np.asarray(kappa)
    w = int(RAMP_M / DS)
    box = np.ones(w) / w
    for _ in range(2):  # circular convolution keeps the total turning
        kap = np.convolve(np.r_[kap[-w:], kap, kap[:w]], box, mode="same")[w:-w]
    return kap * (2 * math.pi / (kap.sum() * DS)), straights


def _integrate(kap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    heading = np.cumsum(kap) * DS - kap * DS / 2  # midpoint of each step
    step = np.stack([np.cos(heading), np.sin(heading)], 1) * DS
    return np.cumsum(step, 0) - step, heading


def _close(pieces: list, straights: list, heading: np.ndarray, gap: np.ndarray) -> list | None:
    """Pieces with straight lengths changed (minimum norm, each kept >= MIN_STRAIGHT_M) to cancel ``gap``."""
    idx = [i for i, p in enumerate(pieces) if p[2]]
    u = np.array([[math.cos(heading[(a + b) // 2]), math.sin(heading[(a + b) // 2])] for a, b in straights]).T
    lengths = np.array([pieces[i][0] for i in idx])
    free = np.ones(len(idx), bool)
    delta = np.zeros(len(idx))
    for _ in range(len(idx)):
        target = -gap - u[:, ~free] @ delta[~free]
        a = u[:, free]
        gram = a @ a.T
        if free.sum() < 2 or np.linalg.cond(gram) > 1e3:
            return None
        delta[free] = a.T @ np.linalg.solve(gram, target)
        low = free & (lengths + delta < MIN_STRAIGHT_M)
        if not low.any():
            out = list(pieces)
            for j, i in enumerate(idx):
                out[i] = (float(lengths[j] + delta[j]), 0.0, True)
            return out
        delta[low] = MIN_STRAIGHT_M - lengths[low]
        free &= ~low
    return None


def too_close(points: np.ndarray, clearance: float) -> bool:
    """Whether two stretches further apart along the road than pi/2 * clearance come within ``clearance``."""
    step = max(1, int(round(1.0 / DS)))
    p = points[::step]
    return closest_overlap(p, np.arange(len(p)) * DS * step, len(p) * DS * step, clearance) is not None


def make_layout(rng: np.random.Generator, cfg: WorldGenConfig, road_width: float, shoulder: float) -> Layout:
    """A closed centre line for a road of this width (deterministic for the generator's state)."""
    clearance = road_width + 2 * shoulder + cfg.clearance_margin_m
    # narrow roads leave the autopilot less room to run wide out of a hairpin: 1.5 m more radius per metre
    narrow = cfg.narrow_radius_m_per_m * max(0.0, cfg.two_lane_min_width_m - road_width)
    hairpin_r = max(cfg.min_radius_m * 1.04 + narrow, clearance / 2 + 0.5, road_width / 2 + shoulder + 1.5)
    for _ in range(cfg.max_attempts):
        drawn = _pieces(rng, cfg, hairpin_r)
        if drawn is None:
            continue
        pieces, feats = drawn
        target = rng.uniform(cfg.min_length_m * 1.05, cfg.max_length_m * 0.95)
        arcs = sum(p[0] for p in pieces if not p[2])
        budget = target - arcs
        n_str = sum(p[2] for p in pieces)
        if budget < n_str * MIN_STRAIGHT_M:
            continue
        weights = rng.dirichlet(np.full(n_str, 1.5))
        it = iter(weights)
        pieces = [(MIN_STRAIGHT_M + (budget - n_str * MIN_STRAIGHT_M) * next(it), 0.0, True) if p[2] else p
                  for p in pieces]
        kap, straights = _profile(pieces)
        pts, heading = _integrate(kap)
        closed = _close(pieces, straights, heading, pts[-1] + DS * np.array([math.cos(heading[-1]),
                                                                               math.sin(heading[-1])]) - pts[0])
        if closed is None:
            continue
        kap, straights = _profile(closed)
        pts, heading = _integrate(kap)
        n = len(pts)
        end = pts[-1] + DS * np.array([math.cos(heading[-1]), math.sin(heading[-1])])
        pts = pts - np.outer(np.arange(n) / n, end - pts[0])  # the rounding residual, spread over the loop
        length = n * DS
        if not cfg.min_length_m <= length <= cfg.max_length_m or too_close(pts, clearance):
            continue
        a, b = max(straights, key=lambda ab: ab[1] - ab[0])
        return Layout(points=pts - (pts.min(0) + pts.max(0)) / 2, curvature=kap, start_s=(a + b) / 2 * DS,
                      features=feats)
    raise RuntimeError(f"no valid layout in {cfg.max_attempts} attempts (road width {road_width:.1f} m)")
