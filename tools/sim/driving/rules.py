"""Scoring rules as data: what counts as an intervention, how the car is put back, and the lap statistics.

Like the CARLA leaderboard's statistics manager, the thresholds live in one frozen dataclass so an
experiment can state exactly which rules it was scored with (``Rules`` is serialised into every
result). The paper counts interventions and charges 6 s for each (Eq. 1-2):
``eta = (1 - n_int * 6 s / t_lap) * 100 %``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from enum import StrEnum
from typing import TypedDict

import numpy as np

from tools.sim.track.cones import CONE_RADIUS
from tools.sim.track.road import Projection, Track
from tools.sim.vehicle.kinematic import kmh_to_mps


class Cause(StrEnum):
    """Why a person had to take over."""

    OFF_ROAD = "off_road"  # car centre beyond the road edge + margin
    CONE = "cone"  # the body touched a cone
    STUCK = "stuck"  # standing still too long
    WRONG_WAY = "wrong_way"  # heading against the lap direction too long
    SPIN_OUT = "spin_out"  # sliding sideways: body slip angle beyond the limit too long (dynamic car)


@dataclass(frozen=True)
class Rules:
    """Thresholds of the referee. Distances in metres, times in simulated seconds."""

    seconds_per_intervention: float = 6.0  # paper Eq. 2 (after NVIDIA's PilotNet paper)
    offroad_margin_m: float = 0.5  # beyond half the road width
    cone_radius_m: float = CONE_RADIUS  # base of the traffic cone the renderer draws
    stuck_speed_kmh: float = 1.0
    stuck_time_s: float = 5.0
    wrong_way_deg: float = 100.0
    wrong_way_time_s: float = 2.0
    # A car whose velocity points this far from its heading is spinning, not cornering (a saloon's
    # body slip stays under ~5 deg at its grip limit); a person takes over when it lasts this long.
    spin_out_slip_deg: float = 30.0
    spin_out_time_s: float = 0.25
    reset_ahead_m: float = 5.0  # the person puts the car back this far along the lap
    reset_speed_kmh: float = 15.0  # ... rolling at this speed
    reset_cone_clearance_m: float = 3.0  # ... and never right on top of a cone

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


#: The rules every run uses unless an experiment says otherwise.
DEFAULT_RULES = Rules()
#: The degree of autonomy (%) every drive is to reach: each public recording in the closed loop (rbc data
#: crossval), each unseen world (rbc dagger).
TARGET_ETA = 95.0


def degree_of_autonomy(interventions: int, lap_time_s: float, rules: Rules = DEFAULT_RULES) -> tuple[float, bool]:
    """Paper Eq. 1-2 in percent, clamped at 0; returns (eta, clamped)."""
    if lap_time_s <= 0:
        return (100.0, False) if interventions == 0 else (0.0, True)
    eta = (1.0 - interventions * rules.seconds_per_intervention / lap_time_s) * 100.0
    return (max(0.0, eta), eta < 0.0)


def angle_diff(a: float, b: float) -> float:
    """Smallest signed difference a - b of two angles in radians."""
    return math.remainder(a - b, math.tau)


class InterventionRecord(TypedDict):
    """A take-over as a run's record holds it."""

    cause: str
    s: float
    x: float
    y: float
    t: float


@dataclass(frozen=True)
class Intervention:
    cause: Cause
    s: float  # arc length of the track (metres, default direction)
    x: float
    y: float
    t: float  # simulated seconds since the start of the run

    def to_dict(self) -> InterventionRecord:
        return {"cause": str(self.cause), "s": round(self.s, 2), "x": round(self.x, 2), "y": round(self.y, 2),
                "t": round(self.t, 3)}


def body_hits(cx: float, cy: float, yaw: float, length: float, width: float, points: np.ndarray,
              radius: float) -> np.ndarray:
    """Indices of ``points`` (n, 2) whose disc of ``radius`` touches the car's rectangle."""
    if len(points) == 0:
        return np.empty(0, dtype=np.intp)
    d = points - (cx, cy)
    c, s = math.cos(yaw), math.sin(yaw)
    along = d[:, 0] * c + d[:, 1] * s
    across = -d[:, 0] * s + d[:, 1] * c
    ex = np.maximum(np.abs(along) - 0.5 * length, 0.0)
    ey = np.maximum(np.abs(across) - 0.5 * width, 0.0)
    return np.flatnonzero(ex * ex + ey * ey <= radius * radius)


class TrackFollower:
    """Incremental projection of a moving point onto the centre line.

    A car moves well under a metre per physics frame, so walking from the previous sample to the
    nearest one gives :meth:`Track.project`'s answer about ten times faster; when the point jumps
    (a reset, a far excursion) it falls back to the full search.
    """

    def __init__(self, track: Track, x: float, y: float) -> None:
        self.track = track
        self._x = track.centerline[:, 0].tolist()
        self._y = track.centerline[:, 1].tolist()
        self._tx = track.tangents[:, 0].tolist()
        self._ty = track.tangents[:, 1].tolist()
        self._n = len(self._x)
        self.i = 0
        self.jump(x, y)

    def jump(self, x: float, y: float) -> Projection:
        """Full search (after a teleport)."""
        p = self.track.project(x, y)
        self.i = int(round(p.s / self.track.spacing)) % self._n
        return self.project(x, y)

    def _d2(self, i: int, x: float, y: float) -> float:
        i %= self._n
        return (self._x[i] - x) ** 2 + (self._y[i] - y) ** 2

    def project(self, x: float, y: float) -> Projection:
        n, i = self._n, self.i
        d = self._d2(i, x, y)
        for step in (1, -1):
            for _ in range(64):
                dn = self._d2(i + step, x, y)
                if dn >= d:
                    break
                i, d = (i + step) % n, dn
            else:
                return self.jump(x, y)
        if d > (2.0 * self.track.road_width) ** 2:
            p = self.track.project(x, y, i * self.track.spacing)
            self.i = int(round(p.s / self.track.spacing)) % n
            return p
        self.i = i
        best: tuple[float, int, int, float, float, float] | None = None
        for a in ((i - 1) % n, i):
            b = (a + 1) % n
            sx, sy = self._x[b] - self._x[a], self._y[b] - self._y[a]
            f = ((x - self._x[a]) * sx + (y - self._y[a]) * sy) / (sx * sx + sy * sy)
            f = min(1.0, max(0.0, f))
            qx, qy = self._x[a] + f * sx, self._y[a] + f * sy
            d2 = (x - qx) ** 2 + (y - qy) ** 2
            if best is None or d2 < best[0]:
                best = (d2, a, b, f, qx, qy)
        assert best is not None  # the loop above runs twice
        _, a, b, f, qx, qy = best
        tx = self._tx[a] * (1 - f) + self._tx[b] * f
        ty = self._ty[a] * (1 - f) + self._ty[b] * f
        norm = math.hypot(tx, ty)
        tx, ty = tx / norm, ty / norm
        s = (a * self.track.spacing + f * self.track.spacing) % self.track.length
        return Projection(s, (x - qx) * -ty + (y - qy) * tx, math.atan2(ty, tx))


class Referee:
    """Watches the car every physics frame and says when a person would take over.

    ``direction`` is +1 when the lap is driven in the track's default direction, -1 when the car
    was spawned reversed: "wrong way" is judged against it.
    """

    def __init__(self, rules: Rules, road_width: float, direction: int, cones: np.ndarray,
                 car_length: float, car_width: float) -> None:
        self.rules = rules
        self.half_width = 0.5 * road_width
        self.direction = direction
        self.cones = cones if cones is not None else np.empty((0, 2))
        self.car_length, self.car_width = car_length, car_width
        self._stuck_speed = kmh_to_mps(rules.stuck_speed_kmh)
        self._wrong_way = math.radians(rules.wrong_way_deg)
        self._spin_slip = math.radians(rules.spin_out_slip_deg)
        self.reset_timers()

    def reset_timers(self) -> None:
        self.still_s = 0.0
        self.wrong_s = 0.0
        self.spin_s = 0.0

    def check(self, dt: float, cx: float, cy: float, yaw: float, speed: float, cte: float,
              track_heading: float, slip: float = 0.0) -> Cause | None:
        """One physics frame; returns the cause of an intervention or None. ``slip``: body slip angle, rad."""
        if abs(cte) > self.half_width + self.rules.offroad_margin_m:
            return Cause.OFF_ROAD
        if len(self.cones) and len(body_hits(cx, cy, yaw, self.car_length, self.car_width, self.cones,
                                             self.rules.cone_radius_m)):
            return Cause.CONE
        self.still_s = self.still_s + dt if speed < self._stuck_speed else 0.0
        if self.still_s >= self.rules.stuck_time_s - 1e-9:  # whole frames: 300 x 1/60 s is 5 s
            return Cause.STUCK
        lap_heading = track_heading if self.direction > 0 else track_heading + math.pi
        if abs(angle_diff(yaw, lap_heading)) > self._wrong_way and speed > self._stuck_speed:
            self.wrong_s += dt
        else:
            self.wrong_s = 0.0
        if self.wrong_s >= self.rules.wrong_way_time_s - 1e-9:
            return Cause.WRONG_WAY
        self.spin_s = self.spin_s + dt if abs(slip) > self._spin_slip and speed > self._stuck_speed else 0.0
        if self.spin_s >= self.rules.spin_out_time_s - 1e-9:
            return Cause.SPIN_OUT
        return None
