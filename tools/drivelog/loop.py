"""The closed loop: a driver steers a car along a recorded drive and sees the re-projected recorded frames.

The car moves at the recorded speed, capped at the speed drive_server deploys at; its state is its arc
length ``s`` along the recorded path (:mod:`tools.drivelog.path`), its lateral offset ``e`` (m, + right)
and heading error ``psi`` (rad, + right). Each step it is shown the recorded frame taken at or just
behind ``s``, re-projected to the car's offset, heading and the distance past that frame, and the
driver's steering moves it (Frenet-frame kinematics of a bicycle along a path of curvature ``kappa_l``):

    ds = v dt cos(psi) / (1 - e kappa_l),   de = v dt sin(psi),   dpsi = v dt kappa_car - kappa_l ds

A person takes over when the car leaves the road, its side past an edge line found in the recorded frame
(:mod:`tools.drivelog.road`; ``lane="road"``), or, as NVIDIA's DAVE-2 evaluation did on roads with lanes,
when ``|e|`` exceeds 1 m from the driver's own line (``lane="path"``); the person puts the car back on the
recorded path and drives it along that path for the 6 s that every take-over costs (the paper's Eq. 1-2:
an interference takes 6 s), then hands back. DAVE-2's simulator handed back at once (``handback_s=0``), so
a spot the model cannot drive (the bridge, a faded edge line) was charged 6 s again every few frames, for
what a person beside the car meets as one take-over. Where the recorded driver left the road (onto the
dirt: :attr:`RoadEdges.off_road`) there is no road to keep to: the person drives the recorded path there,
and that time is neither the driver's nor counted (``LoopResult.off_road_s``). Where the recorded driver
reversed (:func:`tools.drivelog.path.reversing`: turning round at a road's end, backing away from a wall, the
back-and-forth of a three-point turn) the recorded path is not one a car driving forward can follow: with
``LoopRules.person_reverses`` the person drives the recorded path there, and the leg forwards at full lock
that completes the turn, and hands back on it; that time is not counted either (``LoopResult.reversing_s``).

The view is re-projected from the nearest of the three recorded cameras: the left and right ones are real
views 0.95 m to each side, so a car up to about 1.4 m off the driver's line is never shown a view moved
more than 0.5 m from a real one (``views="nearest"``; ``"centre"``: the centre camera alone, as DAVE-2).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from protocol.camera import CAR_HALF_WIDTH_M
from protocol.errors import BadValue
from protocol.facts import DEPLOY_SPEED_KMH
from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera, ViewSynthesizer
from tools.drivelog.path import WHEELBASE_M, RecordedDrive, advance, curvature, reversing
from tools.drivelog.road import RoadEdges
from tools.sim.driving.rules import Rules, degree_of_autonomy

#: Below this speed (m/s) the car is standing or creeping: time there is not counted as driving.
MOVING_MPS = 1.0
#: A car slower than the recorded one takes several steps per frame; this many at most (a stuck loop ends).
MAX_STEPS_PER_FRAME = 40


#: The ranges :class:`LoopRules` accepts: field -> (its command-line flag, lowest, highest, unit).
RULE_RANGES: dict[str, tuple[str, float, float, str]] = {
    "max_offset_m": ("--max-offset", 0.05, 10.0, "metres"),
    "handback_s": ("--handback", 0.0, 60.0, "seconds"),
    "speed_limit_kmh": ("--speed-limit", 0.0, 300.0, "km/h (0: the recorded speed)"),
    "wheelbase_m": ("--wheelbase", 1.0, 20.0, "metres"),
}


@dataclass(frozen=True)
class LoopRules:
    """What counts as leaving the lane, and the car. Distances in metres."""

    # "road": a take-over when the car's side passes an edge line of the road; "path": when the car is more
    # than max_offset_m off the driver's own line (DAVE-2's 1 m, on roads whose lanes are about the car's width)
    lane: str = "road"
    max_offset_m: float = 1.0
    half_width_m: float = CAR_HALF_WIDTH_M  # the car, 1.9 m wide (protocol.camera)
    # where the recorded driver was at the edge already, the car may still move this far towards it
    min_margin_m: float = 0.5
    views: str = "nearest"  # re-project the nearest of the three cameras ("centre": the centre camera only)
    wheelbase_m: float = WHEELBASE_M
    # the car's speed: the recorded one capped here, km/h (0: as recorded). 25: drive_server's default limit,
    # the speed a model is deployed at (the paper's 25 km/h)
    speed_limit_kmh: float = DEPLOY_SPEED_KMH
    seconds_per_intervention: float = Rules.seconds_per_intervention  # the paper's Eq. 1 (after DAVE-2)
    # after a take-over the person drives the recorded path this long (s of the log) before handing back: the
    # time Eq. 2 charges for it (0: at once, as DAVE-2's simulator; the measure before December 2026)
    handback_s: float = Rules.seconds_per_intervention
    # where the recorded driver reversed (tools.drivelog.path.reversing) the person drives the recorded path, and
    # that time is not counted (False: the driver is asked to follow it forwards, the measure before #52)
    person_reverses: bool = True

    def __post_init__(self) -> None:
        """The one check of the rules, whichever command (``rbc drive-log``, ``rbc data crossval``) made them."""
        for name, (flag, lo, hi, unit) in RULE_RANGES.items():
            value = getattr(self, name)
            if not lo <= value <= hi:
                raise BadValue(f"{flag} must be {lo:g}..{hi:g} {unit}, got {value:g}")
        if self.lane not in ("road", "path"):
            raise BadValue(f"unknown lane rule {self.lane!r} (road or path)")
        if self.views not in ("nearest", "centre"):
            raise BadValue(f"unknown views {self.views!r} (nearest or centre)")



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
    limits: tuple[float, float] | None = None  # offsets at which the car leaves the lane, left and right


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
    off_road_s: float = 0.0  # log time where the recorded driver was off the road: driven by the person, not counted
    limits: np.ndarray | None = None  # (steps, 2): the offsets (m) at which a take-over came, left and right
    person: np.ndarray | None = None  # (steps,) True where a person drove after a take-over (rules.handback_s)
    # per take-over, the car's views in the seconds before it, oldest first (``drive``'s ``history_s``)
    before_takeovers: list[list[Snapshot]] = field(default_factory=list)
    reversing_s: float = 0.0  # log time where the recorded driver reversed: driven by the person, not counted

    @property
    def interventions(self) -> int:
        return len(self.takeovers)

    @property
    def eta(self) -> float:
        eta, _ = degree_of_autonomy(self.interventions, self.driving_time_s,
                                    Rules(seconds_per_intervention=self.rules.seconds_per_intervention))
        return eta

    @property
    def offset_rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.offsets ** 2))) if len(self.offsets) else 0.0


def lane_limits(rules: LoopRules, road: RoadEdges | None, n: int) -> np.ndarray:
    """(n, 2): per recorded frame, the offsets from the driver's line at which the car has left the lane."""
    if rules.lane == "path":
        return np.tile([-rules.max_offset_m, rules.max_offset_m], (n, 1))
    if road is None or len(road) != n:
        raise ValueError("the road rule needs the road's edges in every frame")
    left = np.minimum(road.left_m + rules.half_width_m, -rules.min_margin_m)
    right = np.maximum(road.right_m - rules.half_width_m, rules.min_margin_m)
    return np.stack([left, right], axis=1)


def _view(synth: ViewSynthesizer, drive_log: RecordedDrive, i: int, e: float, psi: float, forward: float,
          rules: LoopRules, camera: UnityCamera, pitch_deg: float | None = None) -> np.ndarray:
    """The view from offset ``e``: re-projected from the nearest recorded camera (see the module docstring), the
    ground ahead at ``pitch_deg`` (None: the camera's)."""
    centre = read_jpeg_file(drive_log.frames[i])
    side = "left" if e < 0 else "right"
    source = drive_log.side_frame(i, side) if rules.views == "nearest" and abs(e) > camera.side_offset_m / 2 else None
    if source is None:
        return synth.view(centre, e, psi, forward, pitch_deg=pitch_deg)
    moved = e + camera.side_offset_m if side == "left" else e - camera.side_offset_m
    return synth.view(read_jpeg_file(source), moved, psi, forward, bonnet=centre, pitch_deg=pitch_deg)


def drive(drive_log: RecordedDrive, driver: Driver, rules: LoopRules = LoopRules(),
          camera: UnityCamera = DEFAULT_CAMERA, snapshots: int = 8,
          on_step: Callable[[int], None] | None = None, road: RoadEdges | None = None,
          history_s: float = 0.0) -> LoopResult:
    """Run ``driver`` along every session of the recorded drive, one step per recorded frame interval.

    The car drives at the recorded speed capped at ``rules.speed_limit_kmh`` (0: no cap), so where the
    person drove faster it takes more steps than there are frames. ``snapshots`` evenly spaced views are
    kept (plus the view before each take-over, up to the same number). ``on_step(i)``: the frame reached.
    ``road``: the road's edges in every frame (:func:`tools.drivelog.road.estimate_road`), for ``lane="road"``.
    ``history_s``: also keep, for each take-over, the car's views of that many seconds before it (log time).
    """
    synth = ViewSynthesizer(camera)
    frame_limits = lane_limits(rules, road, len(drive_log))
    limits: list[np.ndarray] = []
    n = len(drive_log)
    cap = rules.speed_limit_kmh / 3.6 if rules.speed_limit_kmh > 0 else math.inf
    offsets: list[float] = []
    headings: list[float] = []
    steer: list[float] = []
    person: list[bool] = []
    takeovers: list[Takeover] = []
    shots: list[Snapshot] = []
    recent: deque[tuple[float, Snapshot]] = deque()  # (log time, view) of the last history_s seconds
    before: list[list[Snapshot]] = []
    keep = set(np.linspace(0, n - 1, snapshots + 2).astype(int)[1:-1]) if snapshots else set()
    k_path = curvature(drive_log.steering, rules.wheelbase_m)
    # where the recorded driver left the road (onto the dirt) there is no road to keep to: the person drives
    # the recorded path there, and that time is neither the driver's nor counted
    off_road = road.off_road if rules.lane == "road" and road is not None and road.off_road is not None \
        else np.zeros(n, bool)
    # where the recorded driver reversed, the recorded path is not one to follow forwards: the person drives it
    backwards = reversing(drive_log) if rules.person_reverses else np.zeros(n, bool)
    # the ground's pitch in each frame where the road finder measured it (hills: tools.drivelog.pitch)
    pitch = road.pitch_deg if road is not None else None
    moving_time = off_road_time = reversing_time = 0.0
    for session in np.unique(drive_log.session):
        steps = drive_log.session_range(int(session))
        arc = drive_log.arc[steps.start:steps.stop]
        s, e, psi = 0.0, 0.0, 0.0
        last = -1
        person_until = -1.0  # log time (s) until which a person drives after a take-over
        recent.clear()
        clock = 0.0
        for _ in range(MAX_STEPS_PER_FRAME * len(steps)):
            i = steps.start + max(0, int(np.searchsorted(arc, s, side="right")) - 1)
            if drive_log.dt[i] <= 0:  # the session's last frame
                break
            v, dt = min(drive_log.speed[i], cap), drive_log.dt[i]
            clock += dt
            # after a take-over, where the recorded driver was off the road or reversed: the recorded path, the
            # driver is not asked
            by_person = clock <= person_until or bool(off_road[i]) or bool(backwards[i])
            view = None if by_person else _view(synth, drive_log, i, e, psi, s - drive_log.arc[i], rules, camera,
                                                None if pitch is None else float(pitch[i]))
            delta = float(drive_log.steering[i]) if view is None else float(driver(view, i))
            offsets.append(e)
            limits.append(frame_limits[i])
            headings.append(math.degrees(psi))
            steer.append(delta)
            person.append(by_person)
            if v >= MOVING_MPS and off_road[i]:
                off_road_time += dt
            elif v >= MOVING_MPS and backwards[i]:
                reversing_time += dt
            elif v >= MOVING_MPS:
                moving_time += dt
            k_car = k_path[i] if by_person else curvature(delta, rules.wheelbase_m)
            s, e, psi = advance(s, e, psi, v, dt, float(k_car), float(k_path[i]))
            if backwards[i] and not off_road[i]:
                e, psi = 0.0, 0.0  # the person drives the recorded path, and hands back on it
            over = not frame_limits[i, 0] <= e <= frame_limits[i, 1]
            fresh = i != last and i in keep
            if history_s > 0 and view is not None:
                recent.append((clock, Snapshot(i, view, offsets[-1], headings[-1], delta, over,
                                               (float(frame_limits[i, 0]), float(frame_limits[i, 1])))))
            while recent and recent[0][0] < clock - history_s:
                recent.popleft()
            if view is not None and (fresh or (over and sum(x.takeover for x in shots) < snapshots)):
                shots.append(Snapshot(i, view, offsets[-1], headings[-1], delta, over,
                                      (float(frame_limits[i, 0]), float(frame_limits[i, 1]))))
            if over:
                takeovers.append(Takeover(i, moving_time, e, len(offsets) - 1))
                if history_s > 0:
                    before.append([shot for _, shot in recent])
                    recent.clear()
                e, psi = 0.0, 0.0  # a person puts the car back on the recorded path
                person_until = clock + rules.handback_s  # ... and drives it there before handing back
            if on_step and i != last:
                on_step(i)
            last = i
    return LoopResult(len(offsets), moving_time, takeovers, np.array(offsets), np.array(headings),
                      np.array(steer), shots, rules, off_road_time, np.array(limits).reshape(-1, 2),
                      np.array(person, bool), before, reversing_s=reversing_time)
