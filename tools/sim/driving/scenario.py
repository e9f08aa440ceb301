"""What defines a simulated run and what it returns: the scenario, the trace, the result, frame events."""

from __future__ import annotations

import statistics
from dataclasses import asdict, dataclass, field
from typing import TypedDict

import numpy as np

from protocol import SpeedUnit, SteerCommand
from protocol.errors import BadValue
from protocol.facts import DEPLOY_SPEED_KMH
from tools.sim.driving.laps import LapRecord, LapResult
from tools.sim.driving.rules import Intervention, Rules
from tools.sim.render.camera import DEFAULT_RIG, camera_rig
from tools.sim.vehicle.kinematic import VEHICLE_KINDS, VehicleState, kmh_to_mps


@dataclass(frozen=True)
class ScenarioConfig:
    """Everything that defines a run. Angles in degrees, speeds in km/h, times in simulated seconds."""

    track: str = "lake"  # built-in name or path to a track JSON
    laps: int = 1
    light_intensity: float = 1.0
    light_direction_deg: float = 0.0
    cones: int = 0
    cone_seed: int = 0
    spawn_s: float | None = None  # metres along the track; None = the track's start
    yaw_offset_deg: float = 0.0  # + = turned left (counter-clockwise)
    reverse: bool = False  # spawn facing the other way; the lap is then driven in reverse
    speed_limit_kmh: float = DEPLOY_SPEED_KMH  # for in-process drivers built from this config (a server has its own)
    realtime: bool = False
    sim_fps: int = 60
    control_hz: float = 15.0  # lock-step only: one command per 1/control_hz s (the paper logs at 15 Hz)
    seed: int = 0  # camera jitter and the autopilot's reaction times (and the spawn, see spawn_noise)
    # With spawn_noise, every seed but 0 starts the car off its nominal pose by U(-0.5, 0.5) m sideways
    # and U(-3, 3) degrees of yaw, so repeated runs of one experiment differ (rbc eval's mean +- std).
    spawn_noise: bool = False
    max_lap_time_s: float | None = None  # None: 4x the time of a lap at the speed limit, at least 120 s
    speed_unit: str = SpeedUnit.MPH.value  # telemetry speed unit: mph like the stock simulator, or kmh
    # the car: "kinematic" bicycle (no slip) or "dynamic" single-track model with tyre slip (tools.sim.vehicle.dynamics)
    vehicle: str = VEHICLE_KINDS[0]
    # the cameras: "classic" (the first headless rig) or "unity" (the real simulator's, with its bonnet)
    camera: str = DEFAULT_RIG

    def __post_init__(self) -> None:
        if self.laps < 1:
            raise BadValue(f"laps must be >= 1, got {self.laps}")
        if self.sim_fps < 1 or self.control_hz <= 0:
            raise BadValue("sim_fps and control_hz must be positive")
        if not self.realtime:
            ratio = self.sim_fps / self.control_hz
            if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
                raise BadValue(f"control_hz {self.control_hz} must divide sim_fps {self.sim_fps}")
        if self.light_intensity < 0:
            raise BadValue(f"light intensity must be >= 0, got {self.light_intensity}")
        if self.cones < 0:
            raise BadValue(f"cones must be >= 0, got {self.cones}")
        if self.speed_limit_kmh <= 0:
            raise BadValue(f"speed limit must be positive, got {self.speed_limit_kmh} km/h")
        SpeedUnit(self.speed_unit)
        if self.vehicle not in VEHICLE_KINDS:
            raise BadValue(f"vehicle must be one of {', '.join(VEHICLE_KINDS)}, got {self.vehicle!r}")
        camera_rig(self.camera)  # an unknown rig is a ValueError naming the known ones

    @property
    def frames_per_command(self) -> int:
        return max(1, round(self.sim_fps / self.control_hz))

    def lap_time_limit(self, track_length_m: float) -> float:
        if self.max_lap_time_s is not None:
            return self.max_lap_time_s
        return max(120.0, 4.0 * track_length_m / kmh_to_mps(self.speed_limit_kmh))

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


@dataclass(frozen=True)
class Trace:
    """Per physics frame: where the car was, for maps. ``cte`` is from the line it should follow."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    cte: np.ndarray
    speed_kmh: np.ndarray
    lap: np.ndarray


class RunResultRecord(TypedDict):
    """A run as its record holds it (:meth:`RunResult.to_dict`; ``rbc sim --json``, each run of ``rbc eval``)."""

    config: dict[str, object]  # the ScenarioConfig's fields
    rules: dict[str, object]  # the Rules' fields
    driver: str
    laps: list[LapRecord]
    completed: bool
    mean_eta: float
    wall_time_s: float
    sim_time_s: float
    frames: int
    latency_ms_p50: float
    latency_ms_p99: float
    track_length_m: float
    interrupted: bool


@dataclass
class RunResult:
    config: ScenarioConfig
    rules: Rules
    driver: str
    laps: list[LapResult]
    wall_time_s: float
    sim_time_s: float
    frames: int  # telemetry frames sent to the driver
    latency_ms_p50: float  # the driver's reply latency (socket: send to reply, queueing included)
    latency_ms_p99: float
    track_length_m: float
    interrupted: bool = False
    trace: Trace | None = field(default=None, repr=False)
    cones: np.ndarray | None = field(default=None, repr=False)

    @property
    def completed(self) -> bool:
        return len(self.laps) == self.config.laps and all(lap.completed for lap in self.laps)

    @property
    def mean_eta(self) -> float:
        return statistics.fmean(lap.eta for lap in self.laps) if self.laps else 0.0

    def to_dict(self) -> RunResultRecord:
        return {
            "config": self.config.to_dict(), "rules": self.rules.to_dict(), "driver": self.driver,
            "laps": [lap.to_dict() for lap in self.laps], "completed": self.completed,
            "mean_eta": round(self.mean_eta, 3), "wall_time_s": round(self.wall_time_s, 3),
            "sim_time_s": round(self.sim_time_s, 3), "frames": self.frames,
            "latency_ms_p50": round(self.latency_ms_p50, 3), "latency_ms_p99": round(self.latency_ms_p99, 3),
            "track_length_m": round(self.track_length_m, 2), "interrupted": self.interrupted,
        }


@dataclass(frozen=True)
class FrameEvent:
    """Handed to ``on_frame`` for every telemetry frame (pictures, videos)."""

    t: float
    lap: int
    rgb: np.ndarray  # the centre camera, as encoded into the telemetry
    state: VehicleState
    command: SteerCommand  # the command in force when the frame was taken
    intervention: Intervention | None = None  # the latest take-over (the car was put back on the road)
