"""One scenario, driven to the end: the simulator's main loop, the driver pipeline and the results.

``run_scenario(config, driver)`` is what ``rbc sim`` and the robustness experiments call. It is
pure (no globals but read-only caches), deterministic per seed in lock-step mode, and cheap to set
up, so many scenarios can run in parallel processes.

Timing model
  Physics runs at ``sim_fps`` (60 Hz) frames. The Unity simulator emits two telemetries when the
  socket opens and then one per reply, so two frames are always in flight (pipeline depth 2): the
  reply to frame k is applied after frame k+1 was already sent, a one-frame command delay. Every
  driver sees exactly this, the socket driver because it really talks to a server that way, the
  in-process drivers because the session queues their frames the same way, so one model gives the
  same lap over the socket and in-process.

  Lock-step (default): each reply advances the physics one control period (``sim_fps /
  control_hz`` frames) with the new command, then the next frame is rendered and sent. As fast as
  the machine allows and bit-for-bit reproducible.

  Real time (``realtime=True``): simulated time is the driver's measured wall time. While the
  simulator waits for a reply the physics keeps running with the previous command for that long
  (rounded to whole frames, at least one); then the new command applies and the next frame is
  rendered at once, as Unity emits telemetry in its reply handler. A slow model therefore steers
  late, as in the real simulator (the paper's speed-limit experiment depends on it). Not
  reproducible run to run, by nature.
"""

from __future__ import annotations

import logging
import math
import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from protocol import SpeedUnit, SteerCommand, encode_image, encode_telemetry
from protocol.units import from_kmh
from tools.sim.rules import (
    DEFAULT_RULES,
    Cause,
    Intervention,
    LapResult,
    LapScorer,
    Referee,
    Rules,
    TrackFollower,
    body_hits,
)
from tools.sim.track import Track, load_track, place_cones
from tools.sim.vehicle import Vehicle, VehicleParams, VehicleState, kmh_to_mps

log = logging.getLogger(__name__)

#: Frames in flight between simulator and driver (the Unity simulator's behaviour, see module doc).
PIPELINE_DEPTH = 2

__all__ = ["PIPELINE_DEPTH", "FrameEvent", "LapResult", "RunResult", "ScenarioConfig", "Simulation", "Trace",
           "run_scenario"]


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
    speed_limit_kmh: float = 25.0  # for in-process drivers built from this config (a server has its own)
    realtime: bool = False
    sim_fps: int = 60
    control_hz: float = 15.0  # lock-step only: one command per 1/control_hz s (the paper logs at 15 Hz)
    seed: int = 0  # camera jitter and the autopilot's reaction times (and the spawn, see spawn_noise)
    # With spawn_noise, every seed but 0 starts the car off its nominal pose by U(-0.5, 0.5) m sideways
    # and U(-3, 3) degrees of yaw, so repeated runs of one experiment differ (rbc eval's mean +- std).
    spawn_noise: bool = False
    max_lap_time_s: float | None = None  # None: 4x the time of a lap at the speed limit, at least 120 s
    speed_unit: str = SpeedUnit.MPH.value  # telemetry speed unit: mph like the stock simulator, or kmh

    def __post_init__(self) -> None:
        if self.laps < 1:
            raise ValueError(f"laps must be >= 1, got {self.laps}")
        if self.sim_fps < 1 or self.control_hz <= 0:
            raise ValueError("sim_fps and control_hz must be positive")
        if not self.realtime:
            ratio = self.sim_fps / self.control_hz
            if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
                raise ValueError(f"control_hz {self.control_hz} must divide sim_fps {self.sim_fps}")
        if self.light_intensity < 0:
            raise ValueError(f"light intensity must be >= 0, got {self.light_intensity}")
        if self.cones < 0:
            raise ValueError(f"cones must be >= 0, got {self.cones}")
        if self.speed_limit_kmh <= 0:
            raise ValueError(f"speed limit must be positive, got {self.speed_limit_kmh} km/h")
        SpeedUnit(self.speed_unit)

    @property
    def frames_per_command(self) -> int:
        return max(1, round(self.sim_fps / self.control_hz))

    def lap_time_limit(self, track_length_m: float) -> float:
        if self.max_lap_time_s is not None:
            return self.max_lap_time_s
        return max(120.0, 4.0 * track_length_m / kmh_to_mps(self.speed_limit_kmh))

    def to_dict(self) -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
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


@lru_cache(maxsize=16)
def _load_track(name: str, mtime: float) -> Track:
    return load_track(name)


def get_track(name: str) -> Track:
    """Load a track once per process (tracks are immutable); a changed file is re-read."""
    path = Path(name)
    return _load_track(name, path.stat().st_mtime if path.is_file() else 0.0)


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
        self.vehicle = Vehicle(VehicleState(0.0, 0.0, 0.0), self.params)
        self.vehicle.place(x, y, yaw)
        self.follower = TrackFollower(track, x, y)
        self.proj = self.follower.project(x, y)
        self.referee = Referee(rules, track.road_width, self.direction, self.cones, self.params.length_m,
                               self.params.width_m)
        self.scorer = LapScorer(1, rules)
        self._trace: list[tuple[float, float, float, float, float, int]] = []
        self.renderer = None
        if render:
            from tools.sim.render import Renderer
            from tools.sim.world import get_world  # cached: the textures are built once per process

            self.renderer = Renderer(get_world(track, config.light_direction_deg,
                                               self.cones if len(self.cones) else None))

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
        st = self.vehicle.step(command.steering, command.throttle)
        cx, cy = self.vehicle.center
        prev_s = self.proj.s
        self.proj = proj = self.follower.project(cx, cy)
        self._progress(prev_s, proj.s)
        self.t += dt
        lat = proj.cte * self.direction
        self.scorer.sample(dt, st.speed, lat - self.line_offset, lat if self.track.lanes == 2 else None)
        self._trace.append((self.t, cx, cy, lat - self.line_offset, st.speed, self.scorer.lap))
        cause = self.referee.check(dt, cx, cy, st.yaw, st.speed, proj.cte, proj.heading_rad)
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
        from tools.sim.world import Pose

        if self.renderer is None:
            raise RuntimeError("this Simulation was created with render=False")
        cx, cy = self.vehicle.center
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


def run_scenario(config: ScenarioConfig, driver: Any, progress: Callable[[float, float], None] | None = None,
                 on_frame: Callable[[FrameEvent], None] | None = None, rules: Rules = DEFAULT_RULES,
                 render: bool = True) -> RunResult:
    """Drive ``config.laps`` laps with ``driver`` (see :mod:`tools.sim.drivers`) and score them.

    ``progress(done_m, total_m)`` is called about once per simulated second; ``on_frame`` gets every
    telemetry frame. Ctrl-C ends the run early with the laps finished so far (``interrupted``).
    ``render=False`` sends frames without an image: only for drivers that use the ground truth (the
    autopilot), e.g. fast tests of the driving rules.
    """
    from tools.sim.drivers import Frame, Scene

    sim = Simulation(config, rules, render=render)
    fps, per_command = config.sim_fps, config.frames_per_command
    total_m = config.laps * sim.track.length
    latencies: list[float] = []
    frames = 0
    interrupted = False
    wall0 = time.perf_counter()

    def send() -> None:
        nonlocal frames
        rgb = sim.render("center", sim.camera_jitter()) if render else None
        payload = sim.telemetry(encode_image(rgb) if rgb is not None else "")
        driver.send(Frame(payload=payload, t=sim.t, truth=sim.vehicle.state))
        frames += 1
        if on_frame is not None and rgb is not None:
            on_frame(FrameEvent(sim.t, sim.lap, rgb, sim.vehicle.state, sim.command))

    driver.start(Scene(track=sim.track, cones=sim.cones, direction=sim.direction, seed=config.seed,
                       vehicle=sim.params, control_period_s=per_command / fps))
    next_report = 0.0
    try:
        for _ in range(PIPELINE_DEPTH):
            send()
        command = sim.command
        while not sim.done:
            t0 = time.perf_counter()
            reply = driver.receive()
            waited = time.perf_counter() - t0
            latencies.append(reply.latency_s)
            if config.realtime:
                sim.advance(max(1, round(waited * fps)), command)
                if sim.done:
                    break
            if reply.command is not None:  # None: a 'manual' reply, the previous command stays
                command = reply.command
            sim.command = command
            if not config.realtime:
                sim.advance(per_command, command)
                if sim.done:
                    break
            send()
            if progress is not None and sim.t >= next_report:
                next_report = sim.t + 1.0
                progress(min(total_m, max(0.0, sim.progress)), total_m)
    except KeyboardInterrupt:
        interrupted = True
        log.warning("interrupted at t=%.1f s (lap %d); returning the laps finished so far", sim.t, sim.lap)
    finally:
        driver.stop()
    if progress is not None and not interrupted:
        progress(total_m, total_m)
    lat_ms = np.array(latencies) * 1000.0 if latencies else np.zeros(1)
    return RunResult(
        config=config, rules=rules, driver=getattr(driver, "name", type(driver).__name__), laps=sim.laps,
        wall_time_s=time.perf_counter() - wall0, sim_time_s=sim.t, frames=frames,
        latency_ms_p50=float(np.percentile(lat_ms, 50)), latency_ms_p99=float(np.percentile(lat_ms, 99)),
        track_length_m=sim.track.length, interrupted=interrupted, trace=sim.trace(), cones=sim.cones,
    )
