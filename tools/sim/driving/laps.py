"""A lap as the paper scores it: the scorer that accumulates it every physics frame, its result with the
metrics the paper did not have, and that result as a run's record holds it. The rules it is scored by are
:mod:`tools.sim.driving.rules`'s."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TypedDict

from tools.sim.driving.rules import Cause, Intervention, InterventionRecord, Rules, degree_of_autonomy


class LapRecord(TypedDict):
    """A lap as a run's record holds it (:meth:`LapResult.to_dict`)."""

    lap: int
    completed: bool
    lap_time_s: float
    distance_m: float
    eta: float
    eta_clamped: bool
    n_interventions: int
    causes: dict[str, int]
    interventions: list[InterventionRecord]
    mean_speed_kmh: float
    cte_rms_m: float
    cte_max_m: float
    collisions: int
    lane_departures: int


@dataclass
class LapResult:
    """One lap as the paper scores it, plus the metrics the paper did not have."""

    lap: int
    completed: bool  # False: max_lap_time_s ran out first (eta is then over the time driven)
    lap_time_s: float
    distance_m: float  # along the track, in the lap direction
    eta: float  # degree of autonomy, percent (Eq. 1-2)
    eta_clamped: bool  # Eq. 1 went negative and was clamped at 0
    interventions: list[Intervention] = field(default_factory=list)
    mean_speed_kmh: float = 0.0
    cte_rms_m: float = 0.0
    cte_max_m: float = 0.0
    collisions: int = 0  # cone hits
    lane_departures: int = 0  # 2-lane tracks: times the car centre crossed into the opposite lane

    @property
    def n_interventions(self) -> int:
        return len(self.interventions)

    def causes(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for i in self.interventions:
            out[str(i.cause)] = out.get(str(i.cause), 0) + 1
        return out

    def to_dict(self) -> LapRecord:
        return {
            "lap": self.lap, "completed": self.completed, "lap_time_s": round(self.lap_time_s, 3),
            "distance_m": round(self.distance_m, 2), "eta": round(self.eta, 3),
            "eta_clamped": self.eta_clamped, "n_interventions": self.n_interventions,
            "causes": self.causes(), "interventions": [i.to_dict() for i in self.interventions],
            "mean_speed_kmh": round(self.mean_speed_kmh, 3), "cte_rms_m": round(self.cte_rms_m, 4),
            "cte_max_m": round(self.cte_max_m, 4), "collisions": self.collisions,
            "lane_departures": self.lane_departures,
        }


class LapScorer:
    """Accumulates one lap, sampled every physics frame (time-weighted, independent of the control rate)."""

    def __init__(self, lap: int, rules: Rules) -> None:
        self.lap, self.rules = lap, rules
        self.time_s = 0.0
        self.distance_m = 0.0
        self._speed_sum = 0.0
        self._cte_sq = 0.0
        self._cte_max = 0.0
        self._frames = 0
        self._in_wrong_lane = False
        self.lane_departures = 0
        self.interventions: list[Intervention] = []

    def sample(self, dt: float, speed_mps: float, cte_from_line: float, lane_side: float | None) -> None:
        """``cte_from_line``: offset from the line the car should follow; ``lane_side`` > 0: opposite lane."""
        self.time_s += dt
        self._frames += 1
        self._speed_sum += speed_mps
        self._cte_sq += cte_from_line * cte_from_line
        self._cte_max = max(self._cte_max, abs(cte_from_line))
        if lane_side is not None:
            wrong = lane_side > 0
            if wrong and not self._in_wrong_lane:
                self.lane_departures += 1
            self._in_wrong_lane = wrong

    def finish(self, completed: bool) -> LapResult:
        n = max(1, self._frames)
        eta, clamped = degree_of_autonomy(len(self.interventions), self.time_s, self.rules)
        return LapResult(
            lap=self.lap, completed=completed, lap_time_s=self.time_s, distance_m=self.distance_m,
            eta=eta, eta_clamped=clamped, interventions=list(self.interventions),
            mean_speed_kmh=self._speed_sum / n * 3.6, cte_rms_m=math.sqrt(self._cte_sq / n),
            cte_max_m=self._cte_max, collisions=sum(i.cause is Cause.CONE for i in self.interventions),
            lane_departures=self.lane_departures,
        )
