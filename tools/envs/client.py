"""The headless simulator as the environment sees it: start a run, apply a command for a step, look.

Kept apart from the Gymnasium environment as gym-donkeycar keeps its simulator client apart from its
``DonkeyEnv``: this module knows the simulator (:mod:`tools.sim.driving`), the environment only actions,
observations and rewards. The physics, referee, cameras and JPEG are the simulator's and the wire's own,
so a frame here is the frame ``rbc sim`` would send.

A take-over (the referee's intervention) ends the step at once; the simulator has by then put the car
back on the road, so what the step reports and shows is the car one physics frame before, where it
left the road, hit the cone or spun.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from protocol import SpeedUnit, SteerCommand, encode_telemetry, parse_number
from protocol.jpeg import encode_jpeg
from protocol.units import from_kmh, to_kmh
from tools.envs.wire_jpeg import wire_decoder
from tools.envs.worldcache import BuiltWorld, WorldKey, release_albedo, with_fog
from tools.sim.driving.autopilot import Autopilot, AutopilotParams
from tools.sim.driving.rules import angle_diff
from tools.sim.driving.scenario import ScenarioConfig
from tools.sim.driving.simulation import Simulation
from tools.sim.render.world import Pose
from tools.sim.track.road import Projection
from tools.sim.vehicle.kinematic import VehicleState

#: The telemetry's speed unit: the stock simulator's, which drive_server assumes by default.
WIRE_UNIT = SpeedUnit.MPH


@dataclass(frozen=True)
class StepReport:
    """What one step of the simulator did."""

    progress_m: float  # metres driven along the lap (before any take-over)
    out_of_lane_s: float  # seconds with the car's body over its lane's edge
    intervention: str  # "" or the referee's cause (tools.sim.driving.rules.Cause): off_road, cone, ...
    laps_done: bool  # the run's laps are driven
    time_out: bool  # the lap's time limit ran out
    distance_m: float = 0.0  # metres driven over the ground, in any direction
    abs_cte_distance_m2: float = 0.0  # the integral of |cte| (from the car's line) over those metres


@dataclass(frozen=True)
class Episode:
    """One episode's world, drawn by the environment: the built world and the light and fog to see it in."""

    key: WorldKey
    built: BuiltWorld
    light_intensity: float = 1.0
    fog: float = 1.0  # times the world's own fog density


@dataclass(frozen=True)
class _Snapshot:
    state: VehicleState  # rear-axle pose, speed, wheel angle
    proj: Projection  # of the body centre on the centre line (track direction)
    progress: float  # metres along the lap since the spawn


class HeadlessSimClient:
    """One car on one track, driven a step at a time; :meth:`start` begins a new run (an episode)."""

    def __init__(self, track: str, camera: str, cameras: tuple[str, ...], jpeg: bool, *, laps: int = 1,
                 vehicle: str = ScenarioConfig.vehicle, speed_limit_kmh: float = ScenarioConfig.speed_limit_kmh,
                 control_hz: float = ScenarioConfig.control_hz, max_lap_time_s: float | None = None,
                 light_intensity: float = 1.0, cones: int = 0, reverse: bool = False) -> None:
        self.base = ScenarioConfig(track=track, laps=laps, light_intensity=light_intensity, cones=cones,
                                   reverse=reverse, speed_limit_kmh=speed_limit_kmh, control_hz=control_hz,
                                   max_lap_time_s=max_lap_time_s, vehicle=vehicle, camera=camera)
        self.cameras, self.jpeg = cameras, jpeg
        self.sim: Simulation | None = None
        self.expert: Autopilot | None = None
        self._view: _Snapshot | None = None

    def prepare(self) -> None:
        """Build the client's own world (its textures: 1-2 s and about 230 MB, once per process) now rather than
        at the first :meth:`start`, which finds it in the renderer's cache."""
        from tools.sim.render.world import get_world
        from tools.sim.track.cones import place_cones
        from tools.sim.track.files import get_track

        config = self.base
        track = get_track(config.track)
        cones = place_cones(track, config.cones, config.cone_seed) if config.cones else None
        # the world Simulation(config) asks for; without cones its albedo goes as it is lit (no other world needs it)
        get_world(track, config.light_direction_deg, cones, keep_albedo=bool(config.cones))
        if not config.cones:
            release_albedo(track, trim=True)

    @property
    def track_length_m(self) -> float:
        return self._sim.track.length

    @property
    def _sim(self) -> Simulation:
        if self.sim is None:
            raise RuntimeError("HeadlessSimClient.start() was not called")
        return self.sim

    @property
    def _seen(self) -> _Snapshot:
        """Where the car is as the observations see it (after a take-over: where it was before the put-back)."""
        if self._view is None:
            raise RuntimeError("HeadlessSimClient.start() was not called")
        return self._view

    def start(self, seed: int, spawn_s: float | None = None, spawn_noise: bool = True, cone_seed: int = 0,
              world: Episode | None = None) -> None:
        """A new run: the car at ``spawn_s`` metres along the track (None: the start line), ``seed`` drawing the
        spawn's noise, the camera bumps, the track's per-frame look and the autopilot's driving line; ``world``:
        this run's world, sun, light and fog (None: the client's own track, built as ``rbc sim`` builds it)."""
        config = replace(self.base, seed=seed, spawn_s=spawn_s, spawn_noise=spawn_noise, cone_seed=cone_seed)
        if world is None:
            self.sim = sim = Simulation(config)
            if not config.cones:  # the same world every episode: its albedo is never needed again
                release_albedo(sim.track)
        else:
            config = replace(config, track=world.built.path, light_intensity=world.light_intensity,
                             light_direction_deg=world.key.sun_deg)
            self.sim = sim = Simulation(config, render=False)
            from tools.sim.render.renderer import Renderer

            sim.renderer = Renderer(with_fog(world.built.world, world.fog), seed=config.seed, rig=config.camera)
        self.expert = Autopilot(sim.track, sim.direction, sim.cones,
                                replace(AutopilotParams(), speed_kmh=config.speed_limit_kmh), sim.params, seed=seed)
        self._view = _Snapshot(sim.vehicle.state, sim.proj, sim.progress)

    def random_spawn_s(self, rng: np.random.Generator, track: str | None = None) -> float:
        """A spawn point anywhere along the track (None: the client's own), drawn from ``rng``."""
        from tools.sim.track.files import get_track

        return float(rng.uniform(0.0, get_track(track or self.base.track).length))

    # --- stepping -----------------------------------------------------------------------------------
    def step(self, command: SteerCommand, frames: int) -> StepReport:
        """Apply ``command`` for ``frames`` physics frames, or until a take-over or the end of the run."""
        sim = self._sim
        track, direction = sim.track, sim.direction
        lane_half = track.road_width / (2 * track.lanes) - 0.5 * sim.params.width_m  # the centre's room in the lane
        dt = sim.params.dt
        progress0 = sim.progress
        outside = distance = abs_cte_distance = 0.0
        cause = ""
        sim.command = command
        for _ in range(frames):
            if sim.done:
                break
            before = _Snapshot(sim.vehicle.state, sim.proj, sim.progress)
            taken_over = sim.last_intervention
            sim.advance(1, command)
            intervention = sim.last_intervention
            if intervention is not taken_over and intervention is not None:
                cause = str(intervention.cause)
                self._view = before  # the simulator already put the car back: report where it was
                break
            cte = abs(sim.proj.cte * direction - sim.line_offset)
            if cte > lane_half:
                outside += dt
            ds = abs(sim.vehicle.state.speed) * dt
            distance += ds
            abs_cte_distance += cte * ds
        if not cause:
            self._view = _Snapshot(sim.vehicle.state, sim.proj, sim.progress)
        laps_done = sim.done and bool(sim.laps) and len(sim.laps) >= sim.config.laps and sim.laps[-1].completed
        return StepReport(progress_m=self._seen.progress - progress0, out_of_lane_s=outside, intervention=cause,
                          laps_done=laps_done, time_out=sim.done and not laps_done and not cause,
                          distance_m=distance, abs_cte_distance_m2=abs_cte_distance)

    def follow(self) -> None:
        """Look at the car where it is now (after a take-over: where the referee put it back), not where the
        last step ended."""
        sim = self._sim
        self._view = _Snapshot(sim.vehicle.state, sim.proj, sim.progress)

    # --- looking ------------------------------------------------------------------------------------
    def render(self, rows: tuple[int, int] | None = None) -> dict[str, np.ndarray]:
        """The cameras' frames (RGB uint8, 160x320) at the car's pose, as the renderer draws them (``rows``: only
        those rows are wanted, the others are left unspecified; see :meth:`Renderer.render`)."""
        sim = self._sim
        st = self._seen.state
        if sim.renderer is None:
            raise RuntimeError("this Simulation was created with render=False")
        half = 0.5 * sim.params.wheelbase_m  # the body centre is half a wheelbase ahead of the rear axle
        pose = Pose(st.x + half * math.cos(st.yaw), st.y + half * math.sin(st.yaw), st.yaw)
        pitch, roll = sim.camera_jitter()
        return {cam: sim.renderer.render(pose, camera=cam, light_intensity=sim.config.light_intensity,
                                         pitch_deg=pitch, roll_deg=roll, rows=rows) for cam in self.cameras}

    def wire(self, rgb: np.ndarray) -> tuple[np.ndarray, bytes]:
        """A frame as it arrives over the wire: JPEG at the track's quality (75 like Unity's), decoded by THE
        decode's pixels (:func:`tools.envs.wire_jpeg.wire_decoder`), and its JPEG bytes; with ``jpeg=False`` the
        rendered frame and no bytes."""
        data = self.encode(rgb)
        return (wire_decoder()(data, 1), data) if data else (rgb, data)

    def encode(self, rgb: np.ndarray) -> bytes:
        """The frame's JPEG as the wire would carry it (the track's quality); ``b""`` with ``jpeg=False``."""
        return encode_jpeg(rgb, self._sim.jpeg_quality) if self.jpeg else b""

    # --- ground truth -------------------------------------------------------------------------------
    def wire_speed(self) -> float:
        """The speed the telemetry says (mph, four decimals), parsed as drive_server parses it."""
        st = self._seen.state
        payload = encode_telemetry(math.degrees(st.steer), st.throttle, from_kmh(st.speed * 3.6, WIRE_UNIT), "")
        return parse_number(payload["speed"], "speed")

    def wire_speed_kmh(self) -> float:
        return to_kmh(self.wire_speed(), WIRE_UNIT)

    def expert_steering(self) -> float:
        """The autopilot's steering for the car's state: pure pursuit of its driving line, -1..1 (+ = right).

        The wanted steering, not the keyboard pulses the autopilot records datasets with: a function of the
        state alone (and the run's driving line), which is what a DAgger label must be.
        """
        if self.expert is None:
            raise RuntimeError("HeadlessSimClient.start() was not called")
        return float(self.expert.wanted_steering(self._seen.state))

    def truth(self) -> dict[str, float]:
        """Where the car is against the road: cross-track error from its line (m, + = left), heading error
        (degrees, + = turned left of the lap direction), speed (km/h), progress (m, laps) and time (s)."""
        sim, view = self._sim, self._seen
        lap_heading = view.proj.heading_rad if sim.direction > 0 else view.proj.heading_rad + math.pi
        return {
            "cte_m": view.proj.cte * sim.direction - sim.line_offset,
            "heading_error_deg": math.degrees(angle_diff(view.state.yaw, lap_heading)),
            "speed_kmh": view.state.speed * 3.6,
            "progress_m": view.progress,
            "lap_progress": view.progress / sim.track.length,
            "t_s": sim.t,
        }
