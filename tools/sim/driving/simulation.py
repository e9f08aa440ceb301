"""One car on one track, one physics frame at a time: vehicle, referee, scoring and cameras.

The timing model (lock-step or real time, two frames in flight) is :mod:`tools.sim.driving.session`'s.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from protocol import SpeedUnit, SteerCommand, encode_telemetry
from protocol.units import from_kmh
from tools.sim.driving.laps import LapResult, LapScorer
from tools.sim.driving.rules import DEFAULT_RULES, Cause, Intervention, Referee, Rules, TrackFollower, body_hits
from tools.sim.driving.scenario import ScenarioConfig, Trace
from tools.sim.track.cones import place_cones
from tools.sim.track.files import get_track
from tools.sim.track.road import SURFACE_KINDS
from tools.sim.vehicle.dynamics import make_vehicle
from tools.sim.vehicle.kinematic import VehicleParams, VehicleState, kmh_to_mps

log = logging.getLogger(__name__)


class Simulation:
    """One car on one track: physics, referee, scoring and cameras, advanced one physics frame at a time."""

    def __init__(self, config: ScenarioConfig, rules: Rules = DEFAULT_RULES, params: VehicleParams | None = None,
                 render: bool = True) -> None:
        self.config, self.rules = config, rules
        self.track = track = get_track(config.track)
        self.cones = place_cones(track, config.cones, config.cone_seed) if config.cones else np.zeros((0, 2))
        self.params = params or VehicleParams(physics_hz=config.sim_fps)
        self.direction = -1 if config.reverse else 1
        # the line a careful driver follows, metres left of the lap direction: right-lane centre on 2 lanes
        self.line_offset = -track.road_width / 4 if track.lanes == 2 else 0.0
        self.unit = SpeedUnit(config.speed_unit)
        self.rng = np.random.default_rng(config.seed)
        self.t = 0.0
        self.progress = 0.0  # metres along the lap direction since the spawn
        self.laps: list[LapResult] = []
        self.done = False
        self.command = SteerCommand(0.0, 0.0)
        self.lap_limit_s = config.lap_time_limit(track.length)

        spawn_s = (track.start_s if config.spawn_s is None else config.spawn_s) % track.length
        x, y, heading = self._line_pose(spawn_s)
        yaw = heading + math.radians(config.yaw_offset_deg)
        if config.spawn_noise and config.seed != 0:
            noise = np.random.default_rng([config.seed, 7919])  # own stream: camera jitter stays as it was
            lateral, dyaw = noise.uniform(-0.5, 0.5), math.radians(noise.uniform(-3.0, 3.0))
            x, y, yaw = x - math.sin(heading) * lateral, y + math.cos(heading) * lateral, yaw + dyaw
        self.vehicle = make_vehicle(config.vehicle, VehicleState(0.0, 0.0, 0.0), self.params)
        self.vehicle.place(x, y, yaw)
        # tyre-road friction at every track sample, from its surface kind (what the dynamic car grips with)
        by_kind = [self.params.friction(kind) for kind in SURFACE_KINDS]
        self._friction = [by_kind[k] for k in track.surface_kinds().tolist()]
        self.follower = TrackFollower(track, x, y)
        self.proj = self.follower.project(x, y)
        self.referee = Referee(rules, track.road_width, self.direction, self.cones, self.params.length_m,
                               self.params.width_m)
        self.scorer = LapScorer(1, rules)
        self.last_intervention: Intervention | None = None  # for pictures: the latest take-over, if any
        self._trace: list[tuple[float, float, float, float, float, int]] = []
        self.renderer = None
        if render:
            from tools.sim.render.renderer import Renderer
            from tools.sim.render.world import get_world  # cached: the textures are built once per process

            self.renderer = Renderer(get_world(track, config.light_direction_deg,
                                               self.cones if len(self.cones) else None), seed=config.seed,
                                     rig=config.camera)

    @property
    def jpeg_quality(self) -> int:
        """JPEG quality of this track's camera frames (its ``appearance``; 75 as the Unity simulator)."""
        return self.track.appearance.jpeg_quality

    # --- geometry -----------------------------------------------------------------------------------
    def _line_pose(self, s: float) -> tuple[float, float, float]:
        """Point on the driving line at ``s`` and the lap heading there."""
        x, y, heading = self.track.point_at(s)
        lat = self.line_offset * self.direction  # to track-left
        x, y = x - math.sin(heading) * lat, y + math.cos(heading) * lat
        return x, y, heading if self.direction > 0 else heading + math.pi

    @property
    def lap(self) -> int:
        return self.scorer.lap

    # --- physics --------------------------------------------------------------------------------------
    def advance(self, frames: int, command: SteerCommand) -> None:
        """Run ``frames`` physics frames with ``command`` (stops early when the run is over)."""
        self.command = command
        for _ in range(frames):
            if self.done:
                return
            self._step(command)

    def _step(self, command: SteerCommand) -> None:
        dt = self.params.dt
        self.vehicle.friction = self._friction[self.follower.i]  # the surface under the car (last frame's)
        st = self.vehicle.step(command.steering, command.throttle)
        cx, cy = self.vehicle.centre
        prev_s = self.proj.s
        self.proj = proj = self.follower.project(cx, cy)
        self._progress(prev_s, proj.s)
        self.t += dt
        lat = proj.cte * self.direction
        self.scorer.sample(dt, st.speed, lat - self.line_offset, lat if self.track.lanes == 2 else None)
        self._trace.append((self.t, cx, cy, lat - self.line_offset, st.speed, self.scorer.lap))
        cause = self.referee.check(dt, cx, cy, st.yaw, st.speed, proj.cte, proj.heading_rad, st.slip)
        if cause is not None:
            self._intervene(cause, cx, cy)
        if self.progress >= self.scorer.lap * self.track.length:
            self._finish_lap(completed=True)
        elif self.scorer.time_s >= self.lap_limit_s:
            log.info("lap %d: no finish within %.0f s of simulated time", self.scorer.lap, self.lap_limit_s)
            self._finish_lap(completed=False)
            self.done = True

    def _progress(self, prev_s: float, s: float) -> None:
        L = self.track.length
        ds = ((s - prev_s + L / 2) % L - L / 2) * self.direction
        self.progress += ds
        self.scorer.distance_m += ds

    def _finish_lap(self, completed: bool) -> None:
        self.laps.append(self.scorer.finish(completed))
        if len(self.laps) >= self.config.laps:
            self.done = True
        else:
            self.scorer = LapScorer(self.scorer.lap + 1, self.rules)

    def _intervene(self, cause: Cause, cx: float, cy: float) -> None:
        """A person takes over: the car goes back on the line a few metres on, aligned, rolling."""
        self.scorer.interventions.append(Intervention(cause, self.proj.s, cx, cy, self.t))
        self.last_intervention = self.scorer.interventions[-1]
        log.debug("t=%.2f s: intervention (%s) at s=%.1f m", self.t, cause, self.proj.s)
        s = self.proj.s + self.direction * self.rules.reset_ahead_m
        for _ in range(int(self.track.length)):
            x, y, yaw = self._line_pose(s)
            if not len(body_hits(x, y, yaw, self.params.length_m, self.params.width_m, self.cones,
                                 self.rules.reset_cone_clearance_m)):
                break
            s += self.direction * 1.0
        prev_s = self.proj.s
        self.vehicle.place(x, y, yaw, kmh_to_mps(min(self.rules.reset_speed_kmh, self.config.speed_limit_kmh)))
        self.proj = self.follower.jump(x, y)
        self._progress(prev_s, self.proj.s)
        self.referee.reset_timers()

    # --- cameras and telemetry --------------------------------------------------------------------------
    def camera_jitter(self) -> tuple[float, float]:
        """Pitch and roll (degrees) of this frame: the track's bumpiness, drawn from the scenario's seed."""
        j = self.track.camera_jitter
        if not (j.pitch_deg or j.roll_deg):
            return 0.0, 0.0
        pitch, roll = self.rng.standard_normal(2)
        return float(pitch * j.pitch_deg), float(roll * j.roll_deg)

    def render(self, camera: str = "center", jitter: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        """RGB frame (160, 320, 3) of ``camera`` at the car's current pose."""
        from tools.sim.render.world import Pose

        if self.renderer is None:
            raise RuntimeError("this Simulation was created with render=False")
        cx, cy = self.vehicle.centre
        return self.renderer.render(Pose(cx, cy, self.vehicle.state.yaw), camera=camera,
                                    light_intensity=self.config.light_intensity, pitch_deg=jitter[0],
                                    roll_deg=jitter[1])

    def telemetry(self, image_b64: str) -> dict[str, str]:
        """The payload Unity would send now: wheel angle in degrees, applied throttle, speed in the unit."""
        st = self.vehicle.state
        return encode_telemetry(math.degrees(st.steer), st.throttle, from_kmh(st.speed * 3.6, self.unit), image_b64)

    def trace(self) -> Trace:
        a = np.array(self._trace, dtype=np.float64).reshape(-1, 6)
        return Trace(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4] * 3.6, a[:, 5].astype(np.int32))
