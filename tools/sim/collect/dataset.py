"""Record a training set with the autopilot, in the Udacity simulator's log format.

Output: ``DIR/driving_log.csv`` (no header, ``", "`` separators, absolute image paths, columns
center, left, right, steering -1..1, throttle 0..1, brake 0..1, speed in mph or km/h; left/right
empty with one camera) and ``DIR/IMG/{center,left,right}_YYYY_MM_DD_HH_MM_SS_mmm.jpg`` named by
simulated time, so any Udacity-style training script reads it.

The autopilot decides every physics frame, like a person at a keyboard; rows are recorded at
``rate_hz`` with the steering key axis at that moment as the label (what Unity logs). Each row is
written with one ``write`` after its images exist, so Ctrl-C or a full disk leaves a consistent log:
never a half row, never a row without its images (the images of an unfinished row are removed).
``resume=True`` drives the same laps again and writes only the rows after the last complete one
(the kept rows are checked against what this configuration records; their frames are not rendered
again), so a collection stopped by a full disk or Ctrl-C ends as the uninterrupted one would.
"""

from __future__ import annotations

import datetime as dt
import logging
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from protocol import SpeedUnit
from protocol.datalog_writer import IMAGE_DIR, LOG_NAME, LogWriter, format_row, frame_name, last_row_stamp
from protocol.errors import BadValue
from protocol.facts import CAMERAS, COLLECT_SPEED_KMH
from protocol.jpeg import encode_jpeg
from protocol.rigfile import write_rig
from protocol.units import from_kmh
from tools.sim.driving.autopilot import Autopilot, AutopilotParams
from tools.sim.driving.laps import LapResult
from tools.sim.driving.scenario import ScenarioConfig
from tools.sim.driving.simulation import Simulation
from tools.sim.track.cones import place_cones
from tools.sim.track.files import builtin_tracks, get_track

log = logging.getLogger(__name__)

EPOCH = dt.datetime(2020, 1, 1, 12, 0, 0)  # first timestamp of a new log (fixed: runs are reproducible)


class OutputDirError(BadValue):
    """The output directory is not empty and neither overwrite nor append was asked for (the message says so)."""


@dataclass(frozen=True)
class CollectConfig:
    track: str = "lake"
    laps: int = 1  # per direction
    both_directions: bool = False  # then the same number of laps again, driven in reverse
    cones: int = 0
    cone_seed: int = 0
    cameras: int = 3  # 1 (centre only) or 3
    rate_hz: float = 15.0  # rows per simulated second (the paper's code: every 0.0667 s)
    seed: int = 0
    speed_kmh: float = COLLECT_SPEED_KMH  # the paper's data collection speed
    speed_unit: str = SpeedUnit.MPH.value
    light_intensity: float = 1.0
    light_direction_deg: float = 0.0
    sim_fps: int = 60
    vehicle: str = ScenarioConfig.vehicle  # "kinematic" or "dynamic" (tools.sim.vehicle.dynamics)
    camera: str = ScenarioConfig.camera  # "unity" or "classic" (tools.sim.render.camera.RIGS); DIR/camera_rig.json

    def __post_init__(self) -> None:
        if self.cameras not in (1, 3):
            raise BadValue(f"cameras must be 1 or 3, got {self.cameras}")
        if not 0 < self.rate_hz <= self.sim_fps:
            raise BadValue(f"rate_hz must be in (0, {self.sim_fps}], got {self.rate_hz}")
        if self.laps < 1:
            raise BadValue(f"laps must be >= 1, got {self.laps}")
        SpeedUnit(self.speed_unit)


@dataclass
class CollectResult:
    out_dir: Path
    rows: int
    zero_steer_rows: int
    laps: list[LapResult] = field(default_factory=list)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    interrupted: bool = False

    @property
    def zero_steer_share(self) -> float:
        return self.zero_steer_rows / self.rows if self.rows else 0.0

    @property
    def interventions(self) -> int:
        return sum(lap.n_interventions for lap in self.laps)


def prepare_output(out_dir: Path, overwrite: bool = False, append: bool = False) -> dt.datetime:
    """Create or check the output folder; return the timestamp of the first new row."""
    if overwrite and append:
        raise BadValue("choose overwrite or append, not both")
    out_dir.mkdir(parents=True, exist_ok=True)
    if any(out_dir.iterdir()):
        if overwrite:
            (out_dir / LOG_NAME).unlink(missing_ok=True)
            shutil.rmtree(out_dir / IMAGE_DIR, ignore_errors=True)
        elif not append:
            raise OutputDirError(f"{out_dir} is not empty; pass --overwrite to replace its log and images "
                                 f"or --append to add to them")
    (out_dir / IMAGE_DIR).mkdir(exist_ok=True)
    last = last_row_stamp(out_dir / LOG_NAME) if append else None
    return EPOCH if last is None else last + dt.timedelta(seconds=10)


def kept_rows(out_dir: Path) -> list[str]:
    """The complete rows of an earlier collection in ``out_dir`` whose images all exist, in order; the
    log is cut back to them (a row without its images and everything after it is driven again)."""
    log_path = out_dir / LOG_NAME
    if not log_path.is_file():
        raise OutputDirError(f"--resume: {out_dir} holds no {LOG_NAME} to continue; drop --resume to start")
    text = log_path.read_text(encoding="utf-8")
    lines = text.split("\n")[:-1]  # the part after the last newline is no complete row
    kept: list[str] = []
    for line in lines:
        images = [c.strip() for c in line.split(",")[:3] if c.strip()]
        if not images or not all(Path(i).is_file() and Path(i).stat().st_size for i in images):
            break
        kept.append(line)
    cut = "".join(line + "\n" for line in kept)
    if cut != text:
        log.info("--resume: %s cut back to its %d complete rows", log_path, len(kept))
        with log_path.open("r+b") as fh:
            fh.truncate(len(cut.encode("utf-8")))
    return kept


def collect(config: CollectConfig, out_dir: Path, overwrite: bool = False, append: bool = False,
            progress: Callable[[float, float], None] | None = None, start: dt.datetime | None = None,
            resume: bool = False) -> CollectResult:
    """Drive ``config.laps`` laps (per direction) with the autopilot and record them to ``out_dir``.

    ``start`` is the time of the first row (frame names); by default the fixed epoch, or after the
    last row when appending. Several worlds of one data set each get their own (unique image names).
    ``resume``: continue an earlier collection of the same configuration (see the module docstring).
    """
    out_dir = Path(out_dir).resolve()
    track = get_track(config.track)  # a bad track or cone count is an error before any output exists
    place_cones(track, config.cones, config.cone_seed)
    if resume and (overwrite or append):
        raise BadValue("--resume continues a collection: not with --overwrite or --append")
    kept = kept_rows(out_dir) if resume else []
    first = EPOCH if resume else prepare_output(out_dir, overwrite, append)
    named = config.track if config.track in builtin_tracks() else None  # rbc drive-log finds its road by it
    write_rig(out_dir, config.camera, append=append or resume, track=named)  # before any frame: rbc train reads it
    start = first if start is None else start
    result = CollectResult(out_dir=out_dir, rows=0, zero_steer_rows=0)
    directions = (False, True) if config.both_directions else (False,)
    wall0 = time.perf_counter()
    clock = 0.0  # simulated seconds over all drives (timestamps)
    cameras = CAMERAS[: config.cameras]
    img_dir = out_dir / IMAGE_DIR
    pending: list[Path] = []
    sim: Simulation | None = None
    row = 0  # rows of this collection so far, kept ones included
    with LogWriter(out_dir / LOG_NAME) as writer:
        try:
            for k, reverse in enumerate(directions):
                scenario = ScenarioConfig(
                    track=config.track, laps=config.laps, cones=config.cones, cone_seed=config.cone_seed,
                    reverse=reverse, seed=config.seed + k, speed_limit_kmh=config.speed_kmh,
                    light_intensity=config.light_intensity, light_direction_deg=config.light_direction_deg,
                    sim_fps=config.sim_fps, control_hz=config.sim_fps, vehicle=config.vehicle, camera=config.camera)
                sim = Simulation(scenario)
                pilot = Autopilot(sim.track, sim.direction, sim.cones,
                                  replace(AutopilotParams(), speed_kmh=config.speed_kmh), sim.params,
                                  seed=config.seed * 2 + k)
                total_m = len(directions) * config.laps * sim.track.length
                done_before = k * config.laps * sim.track.length
                dt_frame = sim.params.dt
                next_row = 0.0
                next_report = 0.0
                while not sim.done:
                    command = pilot.update(dt_frame, sim.vehicle.state)
                    if sim.t >= next_row - 1e-9:
                        next_row += 1.0 / config.rate_hz
                        when = start + dt.timedelta(seconds=round(clock + sim.t, 3))
                        jitter = sim.camera_jitter()
                        paths = [img_dir / frame_name(cam, when) for cam in cameras]
                        st = sim.vehicle.state
                        speed = from_kmh(st.speed * 3.6, config.speed_unit)
                        cells = ([str(p) for p in paths], command.steering, max(0.0, command.throttle),
                                 max(0.0, -command.throttle), speed)
                        if row < len(kept):  # recorded before: checked, not rendered again
                            if format_row(*cells) != kept[row]:
                                raise OutputDirError(
                                    f"--resume: row {row + 1} of {out_dir / LOG_NAME} is not what this "
                                    "configuration records (it was collected with other settings); use the "
                                    "same flags as the first run, or a new --out")
                        else:
                            pending = paths
                            for cam, path in zip(cameras, paths, strict=True):
                                path.write_bytes(encode_jpeg(sim.render(cam, jitter), sim.jpeg_quality))
                            writer.write(*cells)
                            pending = []  # from here on an interrupt may orphan images, never a row
                        row += 1
                        result.rows += 1
                        result.zero_steer_rows += command.steering == 0.0
                    sim.advance(1, command)
                    if progress is not None and sim.t >= next_report:
                        next_report = sim.t + 1.0
                        progress(done_before + min(max(0.0, sim.progress), config.laps * sim.track.length), total_m)
                if progress is not None:  # the laps are done: the bar ends at the full distance
                    progress(done_before + config.laps * sim.track.length, total_m)
                clock += sim.t + 10.0
                result.sim_time_s += sim.t
                result.laps.extend(sim.laps)
                for lap in sim.laps:
                    if lap.interventions:
                        log.warning("%s lap %d: the autopilot needed %d intervention(s) %s; the log has a jump there",
                                    "reverse" if reverse else "forward", lap.lap, lap.n_interventions, lap.causes())
                sim = None
        except OSError:  # a full disk, say: the last row's images go, the rows before it stay
            for path in pending:
                path.unlink(missing_ok=True)
            log.warning("stopped: %d complete rows in %s (continue with the same command plus --resume)",
                        result.rows, out_dir / LOG_NAME)
            raise
        except KeyboardInterrupt:
            result.interrupted = True
            if sim is not None:  # the drive that was cut short: its time and finished laps count too
                result.sim_time_s += sim.t
                result.laps.extend(sim.laps)
            for path in pending:  # images of a row that was never written
                path.unlink(missing_ok=True)
            log.warning("interrupted: %d complete rows in %s (continue with the same command plus --resume)",
                        result.rows, out_dir / LOG_NAME)
    result.wall_time_s = time.perf_counter() - wall0
    return result
