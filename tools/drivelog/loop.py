"""The closed loop: a driver steers a car along a recorded drive and sees the re-projected recorded frames.

The car moves at the recorded speed, capped at the speed drive_server deploys at; its state is its arc
length ``s`` along the recorded path (:mod:`tools.drivelog.path`), its lateral offset ``e`` (m, + right)
and heading error ``psi`` (rad, + right). Each step it is shown the recorded frame taken at or just
behind ``s``, re-projected to the car's offset, heading and the distance past that frame, and the
driver's steering moves it (Frenet-frame kinematics of a bicycle along a path of curvature ``kappa_l``):

    ds = v dt cos(psi) / (1 - e kappa_l),   de = v dt sin(psi),   dpsi = v dt kappa_car - kappa_l ds

A person takes over when ``|e|`` exceeds the lane margin (NVIDIA's DAVE-2 evaluation: 1 m) and puts the
car back on the recorded path; every take-over costs 6 s of autonomy (the paper's Eq. 1).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera, ViewSynthesizer
from tools.drivelog.path import WHEELBASE_M, RecordedDrive, advance, curvature
from tools.sim.driving.rules import degree_of_autonomy

#: Below this speed (m/s) the car is standing or creeping: time there is not counted as driving.
MOVING_MPS = 1.0
#: A car slower than the recorded one takes several steps per frame; this many at most (a stuck loop ends).
MAX_STEPS_PER_FRAME = 40


@dataclass(frozen=True)
class LoopRules:
    """What counts as leaving the lane, and the car. Distances in metres."""

    max_offset_m: float = 1.0  # DAVE-2: a take-over when the car is more than 1 m off the path it should drive
    wheelbase_m: float = WHEELBASE_M
    # the car's speed: the recorded one capped here, km/h (0: as recorded). 25: drive_server's default limit,
    # the speed a model is deployed at (the paper's 25 km/h)
    speed_limit_kmh: float = 25.0
    seconds_per_intervention: float = 6.0  # the paper's Eq. 1 (after DAVE-2)


#: A driver: (synthesized full-size RGB view, index of the recorded frame shown) -> normalised steering.
Driver = Callable[[np.ndarray, int], float]


@dataclass(frozen=True)
class Takeover:
    frame: int  # position in the log (the frame the car had reached)
    time_s: float  # driving time since the start
    offset_m: float
    step: int  # step of the loop (index into ``LoopResult.offsets``)


@dataclass(frozen=True)
class Snapshot:
    """One synthesized view with the state it was seen from, for the strip."""

    step: int
    view: np.ndarray
    offset_m: float
    heading_deg: float
    steering: float
    takeover: bool = False


@dataclass
class LoopResult:
    frames: int  # steps driven (one per recorded frame interval)
    driving_time_s: float
    takeovers: list[Takeover]
    offsets: np.ndarray  # lateral offset at every step (m), before any take-over (steps: see ``drive``)
    headings: np.ndarray  # heading error at every step (deg)
    steering: np.ndarray  # what the driver steered at every step
    snapshots: list[Snapshot] = field(default_factory=list)
    rules: LoopRules = LoopRules()

    @property
    def interventions(self) -> int:
        return len(self.takeovers)

    @property
    def eta(self) -> float:
        from tools.sim.driving.rules import Rules

        eta, _ = degree_of_autonomy(self.interventions, self.driving_time_s,
                                    Rules(seconds_per_intervention=self.rules.seconds_per_intervention))
        return eta

    @property
    def offset_rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.offsets ** 2))) if len(self.offsets) else 0.0


def drive(drive_log: RecordedDrive, driver: Driver, rules: LoopRules = LoopRules(),
          camera: UnityCamera = DEFAULT_CAMERA, snapshots: int = 8,
          on_step: Callable[[int], None] | None = None) -> LoopResult:
    """Run ``driver`` along every session of the recorded drive, one step per recorded frame interval.

    The car drives at the recorded speed capped at ``rules.speed_limit_kmh`` (0: no cap), so where the
    person drove faster it takes more steps than there are frames. ``snapshots`` evenly spaced views are
    kept (plus the view before each take-over, up to the same number). ``on_step(i)``: the frame reached.
    """
    synth = ViewSynthesizer(camera)
    n = len(drive_log)
    cap = rules.speed_limit_kmh / 3.6 if rules.speed_limit_kmh > 0 else math.inf
    offsets: list[float] = []
    headings: list[float] = []
    steer: list[float] = []
    takeovers: list[Takeover] = []
    shots: list[Snapshot] = []
    keep = set(np.linspace(0, n - 1, snapshots + 2).astype(int)[1:-1]) if snapshots else set()
    k_path = curvature(drive_log.steering, rules.wheelbase_m)
    moving_time = 0.0
    for session in np.unique(drive_log.session):
        steps = drive_log.session_range(int(session))
        arc = drive_log.arc[steps.start:steps.stop]
        s, e, psi = 0.0, 0.0, 0.0
        last = -1
        for _ in range(MAX_STEPS_PER_FRAME * len(steps)):
            i = steps.start + max(0, int(np.searchsorted(arc, s, side="right")) - 1)
            if drive_log.dt[i] <= 0:  # the session's last frame
                break
            view = synth.view(read_jpeg_file(drive_log.frames[i]), e, psi, s - drive_log.arc[i])
            delta = float(driver(view, i))
            offsets.append(e)
            headings.append(math.degrees(psi))
            steer.append(delta)
            v, dt = min(drive_log.speed[i], cap), drive_log.dt[i]
            if v >= MOVING_MPS:
                moving_time += dt
            s, e, psi = advance(s, e, psi, v, dt, float(curvature(delta, rules.wheelbase_m)), float(k_path[i]))
            over = abs(e) > rules.max_offset_m
            fresh = i != last and i in keep
            if fresh or (over and sum(x.takeover for x in shots) < snapshots):
                shots.append(Snapshot(i, view, offsets[-1], headings[-1], delta, over))
            if over:
                takeovers.append(Takeover(i, moving_time, e, len(offsets) - 1))
                e, psi = 0.0, 0.0  # a person puts the car back on the recorded path
            if on_step and i != last:
                on_step(i)
            last = i
    return LoopResult(len(offsets), moving_time, takeovers, np.array(offsets), np.array(headings),
                      np.array(steer), shots, rules)
