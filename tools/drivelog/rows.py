"""Driving only some rows of a recording: given ranges (``rbc drive-log --rows``), or the stretches a training run
held out for validation (``--held-out-of RUN_DIR``), so a model can be driven on road it never trained on.

The road is found, and the wheelbase fitted, on the whole recording; then each contiguous stretch of chosen
rows is driven as a session of its own: the car starts on the recorded path at its first frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from protocol.datalog import Sample
from protocol.errors import BadValue
from protocol.rows import RowRange, parse_rows, row_numbers
from tools.drivelog.path import RecordedDrive
from tools.drivelog.road import RoadEdges


def parse_row_ranges(text: str) -> list[RowRange]:
    """``"A-B[,C-D...]"`` (1-based, inclusive, as the manifest's rows) -> the ranges."""
    ranges = [parse_rows(part) for part in text.split(",") if part.strip()]
    if not ranges:
        raise BadValue(f"rows {text!r}: no range given", "give 1-based ranges FIRST-LAST, comma-separated, "
                                                          "e.g. 1-500,900-1200")
    return [r for r in ranges if r is not None]


def rows_mask(samples: Sequence[Sample], ranges: Sequence[RowRange]) -> np.ndarray:
    """Per sample: whether its row of the log (counted as :mod:`protocol.rows` counts) is in ``ranges``."""
    numbers: dict[Path, dict[int, int]] = {}
    out = np.zeros(len(samples), bool)
    for i, s in enumerate(samples):
        if s.log not in numbers:
            numbers[s.log] = row_numbers(s.log)
        row = numbers[s.log].get(s.line, 0)
        out[i] = any(row in r for r in ranges)
    return out


def held_out_mask(samples: Sequence[Sample], run_dir: Path) -> np.ndarray:
    """Per sample: whether the training run in ``run_dir`` held its row out for validation (its ``config.json``
    says which logs it read and how it split them; the split is drawn again, no frame decoded). A run that read
    every Nth row held out stretches of them: the rows between two held-out neighbours are held out too."""
    from models.data.trainingdata import split_logs
    from models.networks.runfiles import RunRecord
    from models.training.train_config import TrainConfig

    record = RunRecord.load(run_dir)
    config = TrainConfig.from_dict(record.config, str(record.config_path))
    dataset, _, val = split_logs(config.data, config.seed, config.data_options())
    spans: dict[Path, list[tuple[int, int]]] = {}
    for run in np.split(val, np.flatnonzero(np.diff(val) != 1) + 1):
        if not len(run):
            continue
        first, last = dataset.samples[run[0]], dataset.samples[run[-1]]
        for log in {first.log, last.log}:  # a stretch across two logs: each its own part
            lines = [dataset.samples[i].line for i in run if dataset.samples[i].log == log]
            spans.setdefault(log, []).append((min(lines), max(lines)))
    return np.array([any(a <= s.line <= b for a, b in spans.get(s.log, ())) for s in samples], bool)


def chosen_rows(drive: RecordedDrive, road: RoadEdges | None, keep: np.ndarray
                ) -> tuple[RecordedDrive, RoadEdges | None]:
    """``drive`` (and its ``road``) cut to the frames in ``keep``: each contiguous stretch of them within a session
    becomes a session of its own, its arc length counted from its first frame."""
    keep = np.asarray(keep, bool)
    if keep.shape != (len(drive),):
        raise ValueError(f"keep: one flag per frame ({len(drive)}), got {keep.shape}")
    idx = np.flatnonzero(keep)
    if not len(idx):
        raise BadValue("no frame of the recording is among the chosen rows")
    # a new stretch where a frame was left out before it or the recording's session changed
    new = np.r_[True, (np.diff(idx) != 1) | (drive.session[idx[1:]] != drive.session[idx[:-1]])]
    session = np.cumsum(new) - 1
    last = np.r_[new[1:], True]
    dt = np.where(last, 0.0, drive.dt[idx])
    step = drive.speed[idx] * dt
    arc = np.zeros(len(idx))
    for i in range(1, len(idx)):
        arc[i] = 0.0 if new[i] else arc[i - 1] + step[i - 1]

    def pick(frames: list | None) -> list | None:
        return None if frames is None else [frames[i] for i in idx]

    cut = RecordedDrive([drive.frames[i] for i in idx], drive.steering[idx], drive.speed[idx], dt, session, arc,
                        pick(drive.left_frames), pick(drive.right_frames),
                        None if drive.brake is None else drive.brake[idx])
    if road is None:
        return cut, None
    return cut, replace(road, left_m=road.left_m[idx], right_m=road.right_m[idx], measured=road.measured[idx],
                        off_road=None if road.off_road is None else road.off_road[idx],
                        pitch_deg=None if road.pitch_deg is None else road.pitch_deg[idx])
