"""Can a world be driven: the autopilot's lap at the collection speed, with either car.

This is what collecting data over a world needs (eta 100 %: no intervention), so every world family
is checked with it (tests and ``rbc world --check``). Rendering is skipped: the autopilot drives on
the ground truth, and the check costs about a second of CPU per kilometre.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from protocol.facts import COLLECT_SPEED_KMH
from tools.sim.driving.drivers import AutopilotDriver
from tools.sim.driving.scenario import ScenarioConfig
from tools.sim.driving.session import run_scenario


@dataclass(frozen=True)
class DriveCheck:
    track: str
    vehicle: str
    eta: float
    interventions: int
    completed: bool
    mean_speed_kmh: float
    lane_departures: int

    @property
    def ok(self) -> bool:
        return self.completed and self.eta == 100.0 and self.interventions == 0 and self.lane_departures == 0


def drive_check(track: str | Path, vehicle: str = "kinematic", speed_kmh: float = COLLECT_SPEED_KMH,
                reverse: bool = False) -> DriveCheck:
    """One autopilot lap of the track file ``track`` (no frames rendered)."""
    result = run_scenario(ScenarioConfig(track=str(track), vehicle=vehicle, speed_limit_kmh=speed_kmh,
                                         reverse=reverse), AutopilotDriver(), render=False)
    lap = result.laps[0]
    return DriveCheck(str(track), vehicle, float(lap.eta), len(lap.interventions), bool(lap.completed),
                      float(lap.mean_speed_kmh), int(lap.lane_departures))
