"""The road file of a recording (``road_edges.csv`` beside its log): where the road's edge lines were in each
centre frame, as ``rbc data road`` found them, so that training can label frames by where the car stood on
the road (a recipe's ``centre_gain`` and ``edge_gain``).

One row per centre frame: its file name, the left and right edge lines' lateral positions from the camera
(m, + right) and whether that frame showed them itself (1) or took them from its neighbours (0).
"""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from protocol.datalog import DataLogError

ROAD_FILE = "road_edges.csv"
HEADER = ("frame", "left_m", "right_m", "measured")


def road_file_for(log: Path) -> Path:
    """The road file that belongs to a driving log (a ``driving_log.csv`` path)."""
    return Path(log).parent / ROAD_FILE


def write_road_file(path: Path, frames: Sequence[Path], left: np.ndarray, right: np.ndarray,
                    measured: np.ndarray) -> Path:
    """Written whole or not at all (temp file, then rename)."""
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh)
        out.writerow(HEADER)
        for f, lo, hi, seen in zip(frames, left, right, measured, strict=True):
            out.writerow([Path(f).name, f"{lo:.3f}", f"{hi:.3f}", int(bool(seen))])
        fh.flush()
        os.fsync(fh.fileno())
    tmp.replace(path)
    return path


def read_road_middles(path: Path) -> dict[str, float]:
    """Frame file name -> lateral position of the road's middle from the camera (m, + right)."""
    try:
        with Path(path).open(newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise DataLogError(f"{path}: cannot read the road file ({exc.strerror or exc})") from None
    if not rows or tuple(rows[0]) != HEADER:
        raise DataLogError(f"{path}: not a road file (its header must be {','.join(HEADER)})")
    out = {}
    for n, row in enumerate(rows[1:], start=2):
        try:
            left, right = float(row[1]), float(row[2])
        except (IndexError, ValueError):
            raise DataLogError(f"{path}: line {n} is not frame,left_m,right_m,measured") from None
        if not (np.isfinite(left) and np.isfinite(right)):
            raise DataLogError(f"{path}: line {n} has a non-finite edge")
        out[row[0]] = (left + right) / 2
    return out
