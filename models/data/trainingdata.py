"""Logs -> decoded frames -> speed filter -> seeded train/validation split: what training, benchmarks and
inspection share, so inspection sees exactly the split training used."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from models.data.behavior import Pipeline
from models.data.framecache import FrameCache, build_cache
from models.data.labels import centred_average
from models.data.split import SplitKind, SplitSpec, make_split
from models.data.turnround import turnround_rows
from protocol.datalog import DataLogError, DataSet, read_logs
from protocol.units import SpeedUnit, to_kmh

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DataOptions:
    """Which rows are used and how they are split. The paper's defaults: every row, random split."""

    split: SplitSpec = field(default_factory=lambda: SplitSpec(SplitKind.RANDOM))
    min_speed: float = 0.0  # rows recorded below this speed are dropped (0: none)
    min_speed_unit: SpeedUnit | str = SpeedUnit.MPH
    speed_unit: SpeedUnit | str = SpeedUnit.MPH  # unit of the log's speed column
    label_smoothing_frames: int = 0  # training labels: centred moving average over this many frames (0: off)
    # every Nth row of the logs (1: all). Neighbouring frames at 15 Hz are near-copies, so a stride keeps the
    # roads and cuts the frame cache N-fold: PilotNet's 200x66 frames of 380,000 rows would need ~46 GB
    row_stride: int = 1
    # recordings held out whole as the validation set (implies the recordings split); the rest trains
    val_data: tuple[str, ...] = ()
    # training labels: plus this much steering per metre that the road's middle lies to the side (read from each
    # recording's road file, rbc data road): drivers each hold a line of their own on a wide road, so the image
    # cannot say how far the car is from that line, only from the road's middle
    centre_gain: float = 0.0
    # keep each sample's road middle (from the road files) for the edge pull of the augmentation
    road_middles: bool = False
    # leave out the rows where the driver turned the car round (models.data.turnround): reversing pairs the
    # picture with the opposite wheel
    drop_turnround: bool = False

    def slow(self, speeds: np.ndarray) -> np.ndarray:
        """Rows slower than ``min_speed``, comparing both speeds in km/h."""
        if self.min_speed <= 0:
            return np.zeros(len(speeds), dtype=bool)
        return to_kmh(np.asarray(speeds, np.float64), self.speed_unit) < to_kmh(self.min_speed, self.min_speed_unit)


@dataclass
class PreparedData:
    dataset: DataSet
    cache: FrameCache
    usable: np.ndarray  # positions of samples whose frames all decoded and that passed the speed filter
    train: np.ndarray  # cache positions of training samples (log order)
    val: np.ndarray  # cache positions of validation samples (log order)
    steering: np.ndarray  # float32, every sample
    has_sides: np.ndarray  # bool, every sample (False when the pipeline uses no side cameras)
    counts: dict[str, int] = field(default_factory=dict)
    split: SplitSpec = field(default_factory=SplitSpec)
    labels: np.ndarray | None = None  # training targets (smoothed steering), every sample; None: ``steering``
    middles: np.ndarray | None = None  # the road's middle from the centre camera (m, + right), every sample
    recording: np.ndarray | None = None  # index of each sample's log in ``dataset.reports``

    def recording_groups(self, positions: np.ndarray) -> np.ndarray:
        """The recording id of each sample at ``positions`` (all zeros for a one-log data set)."""
        return np.zeros(len(positions), np.int64) if self.recording is None else self.recording[positions]

    @property
    def targets(self) -> np.ndarray:
        """What the network is fitted to; validation is always scored against the recorded ``steering``."""
        return self.steering if self.labels is None else self.labels

    def summary(self, options: DataOptions | None = None) -> str:
        """One line: rows read, skipped, dropped and kept, and how the kept ones were split."""
        c = self.counts
        if options is None or options.min_speed > 0:
            unit = f" {SpeedUnit(options.min_speed_unit).value}" if options else ""
            slow = f"{c['slow']} dropped below {options.min_speed if options else 0:g}{unit}"
        else:
            slow = "no speed filter"
        if c.get("turnround"):
            slow += f", {c['turnround']} of turns round dropped"
        gap = f", {c['gap']} dropped beside held-out blocks" if c.get("gap") else ""
        if self.split.kind is SplitKind.RECORDINGS:
            gap = f": {c['val_recordings']} of {c['recordings']} recordings held out"
        stride = f", 1 row in {c['stride']} used" if c.get("stride", 1) > 1 else ""
        return (f"rows: {c['rows']} read, {c['skipped']} skipped (bad rows or missing images){stride}, "
                f"{c['unreadable']} with unreadable frames, {slow}; {c['kept']} kept: "
                f"{c['train']} training + {c['val']} validation ({SplitKind(self.split.kind).value} split{gap})")


def split_logs(data: Sequence[Path | str], seed: int, options: DataOptions = DataOptions()
               ) -> tuple[DataSet, np.ndarray, np.ndarray]:
    """The logs read as training reads them and split in log order, before any frame is decoded or dropped:
    (dataset, training positions, validation positions). Also how ``rbc drive-log --held-out-of`` finds the
    stretches a run held out."""
    dataset = read_logs([*data, *options.val_data])
    if options.row_stride > 1:
        dataset = DataSet(dataset.samples[::options.row_stride], dataset.reports)
    held_out = None
    if options.val_data:
        held_out = np.arange(len(dataset.reports)) >= len(dataset.reports) - len(options.val_data)
    train, val = make_split(len(dataset.samples), seed, options.split, recording_ids(dataset), held_out)
    return dataset, train, val


def prepare_data(data: Sequence[Path | str], pipeline: Pipeline, seed: int, options: DataOptions = DataOptions(),
                 workers: int = 2, progress: Callable[[int, int], None] | None = None) -> PreparedData:
    # split the log as recorded, then drop what is unusable: blocks stay stretches of real time, and runs with
    # other filters (or crops) of the same data hold out the same stretches
    dataset, train, val = split_logs(data, seed, options)
    recording = recording_ids(dataset)
    cameras = ("center", "left", "right") if pipeline.augment.uses_side_cameras else ("center",)
    speeds = np.array([s.speed for s in dataset.samples], np.float64)
    turnround = turnround_mask(dataset, recording, options)
    slow = options.slow(speeds) & ~turnround  # a slow row of a turn round is counted as the turn's
    cache = build_cache(dataset.samples, pipeline.contract, cameras, workers=workers, progress=progress)
    keep = cache.valid & ~slow & ~turnround
    usable = np.flatnonzero(keep)
    if len(usable) < 2:
        raise DataLogError(f"only {len(usable)} samples with readable frames"
                           f"{' at or above the minimum speed' if slow.any() else ''} in {dataset.logs}")
    train, val = train[keep[train]], val[keep[val]]
    if not len(train) or not len(val):
        raise DataLogError(f"{len(train)} training and {len(val)} validation samples left in {dataset.logs}: "
                           "record more, or lower the recipe's [data] min_speed")
    steering = np.array([s.steering for s in dataset.samples], np.float32)
    sides = np.array([s.has_sides for s in dataset.samples], bool) & pipeline.augment.uses_side_cameras
    if pipeline.augment.uses_side_cameras and not sides.any():
        log.warning("no sample has left and right frames: perspective shifts are skipped")
    counts = {"rows": sum(r.rows for r in dataset.reports), "stride": options.row_stride,
              "skipped": sum(len(r.skipped) for r in dataset.reports),
              "unreadable": int((~cache.valid).sum()), "slow": int((slow & cache.valid).sum()),
              "turnround": int((turnround & cache.valid).sum()),
              "kept": int(len(usable)), "train": int(len(train)), "val": int(len(val)),
              "gap": int(len(usable) - len(train) - len(val)),
              "recordings": len(dataset.reports), "val_recordings": int(len(np.unique(recording[val])))}
    labels = None
    if options.label_smoothing_frames > 1:
        labels = smooth_labels(dataset, steering, options.label_smoothing_frames,
                               np.isin(np.arange(len(steering)), train))
    middles = None
    if options.centre_gain or options.road_middles:
        middles = road_middles(dataset, missing_ok=not options.centre_gain)
        if options.centre_gain:
            labels = np.clip((steering if labels is None else labels)
                             + options.centre_gain * middles, -1.0, 1.0).astype(np.float32)
    return PreparedData(dataset, cache, usable, train, val, steering, sides, counts, options.split, labels,
                        recording=recording, middles=middles if options.road_middles else None)


def road_middles(dataset: DataSet, missing_ok: bool = False) -> np.ndarray:
    """Per sample, the road's middle from the camera (m, + right), from each log's road file.

    ``missing_ok``: a log without a road file gives NaN (the edge pull leaves it alone: a two-lane road's
    driver keeps to one lane, not the middle, so only some recordings should be pulled); else an error.
    """
    from models.data.roadfile import ROAD_FILE, read_road_middles, road_file_for

    out = np.zeros(len(dataset.samples), np.float32)
    middles: dict[Path, dict[str, float] | None] = {}
    for i, sample in enumerate(dataset.samples):
        log_path = Path(sample.log)
        if log_path not in middles:
            path = road_file_for(log_path)
            if not path.is_file() and not missing_ok:
                raise DataLogError(f"{log_path.parent} has no {ROAD_FILE}: the centre gain needs the road's edges "
                                   f"(find them first: rbc data road {log_path.parent})")
            middles[log_path] = read_road_middles(path) if path.is_file() else None
        table = middles[log_path]
        out[i] = np.nan if table is None else table.get(Path(sample.center).name, 0.0)
    missing = [str(p.parent) for p, table in middles.items() if table is None]
    if missing and len(missing) == len(middles):
        raise DataLogError(f"no recording has a {ROAD_FILE}: the edge pull needs the road's edges "
                           f"(find them first: rbc data road {missing[0]})")
    if missing:
        log.warning("%d of %d recordings have no %s and get no edge pull: %s", len(missing), len(middles), ROAD_FILE,
                    ", ".join(missing))
    return out


def turnround_mask(dataset: DataSet, recording: np.ndarray, options: DataOptions) -> np.ndarray:
    """Per sample: a row of a turn round (nothing unless ``options.drop_turnround``), found in each log alone."""
    out = np.zeros(len(dataset.samples), bool)
    if options.drop_turnround:
        for r in np.unique(recording).tolist():
            rows = np.flatnonzero(recording == r)
            out[rows] = turnround_rows([dataset.samples[i] for i in rows.tolist()], options.speed_unit)
    return out


def recording_ids(dataset: DataSet) -> np.ndarray:
    """Index into ``dataset.reports`` of each sample's log."""
    index = {r.log: i for i, r in enumerate(dataset.reports)}
    return np.array([index[s.log] for s in dataset.samples], np.int64)


def smooth_labels(dataset: DataSet, steering: np.ndarray, frames: int, use: np.ndarray) -> np.ndarray:
    """Centred moving average of the steering within each log, over the frames marked in ``use`` only
    (training frames: a held-out label never leaks into a training target).

    Keyboard steering is a train of taps (~70 % exact zeros): the same road gets 0 in one frame and
    -0.3 in the next. Its average over ~1 s is what the driver meant, and the best a single frame can
    predict; fitting it lowers the error against the taps themselves.
    """
    out = np.empty_like(steering)
    logs = np.array([str(s.log) for s in dataset.samples])
    for name in dict.fromkeys(logs):
        idx = np.flatnonzero(logs == name)
        out[idx] = centred_average(steering[idx], frames, use[idx]).astype(np.float32)
    out[np.abs(out) < 1e-6] = 0.0  # straight stretches stay exactly zero for the zero-steer balancing
    return out
