"""Traffic cones: their size (the renderer and the referee share it) and their placement on a track."""

from __future__ import annotations

import math

import numpy as np

from protocol.errors import BadValue
from tools.sim.track.road import Track

CONE_RADIUS = 0.25  # metres, base radius of the 0.9 m highway cone the renderer draws


CONE_HEIGHT = 0.9


CONE_START_CLEARANCE = 30.0  # metres of clear road either side of the start line


def place_cones(track: Track, n: int, seed: int, min_spacing: float = 25.0) -> np.ndarray:
    """Positions (n, 2) of ``n`` traffic cones, each blocking about half the road.

    Each cone stands in the middle of one half of the road (``road_width / 4`` off the centre line, side
    drawn at random), so the gap to that edge is narrower than a car and it must pass on the other half.
    Cones are stratified along the track (one per equal slot, jittered inside it) so placements are
    ``min_spacing`` apart, never within :data:`CONE_START_CLEARANCE` of the start; the same seed always
    gives the same cones, a different seed new positions.
    """
    if n < 0:
        raise BadValue(f"number of cones must be >= 0, got {n}")
    if n == 0:
        return np.zeros((0, 2))
    usable = track.length - 2 * CONE_START_CLEARANCE
    slot = usable / n
    if slot < min_spacing:
        raise BadValue(f"{n} cones {min_spacing:g} m apart do not fit on {track.name!r} "
                         f"({usable:.0f} m usable); use fewer cones")
    rng = np.random.default_rng(seed)
    along = track.start_s + CONE_START_CLEARANCE + slot * np.arange(n) + rng.uniform(0, slot - min_spacing, n)
    side = rng.choice([-1.0, 1.0], n)
    out = np.empty((n, 2))
    for k, (s, sgn) in enumerate(zip(along, side, strict=True)):
        x, y, heading = track.point_at(s)
        off = sgn * track.road_width / 4
        out[k] = (x - math.sin(heading) * off, y + math.cos(heading) * off)
    return out
