"""Recorded runs as the monitor sees them: each log's centre frames, decoded and preprocessed exactly as
drive_server does for the steering model, split into runs in driving order (one per world of ``rbc collect``'s
worlds.csv, else one per log), so calibration computes the same one-second means the server does."""

from __future__ import annotations

import csv
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from drive_server.serving.contract import PreprocessContract
from drive_server.serving.preprocess import jpeg_reduction, preprocess
from protocol.datalog import Sample, find_log, read_log
from protocol.errors import BadValue
from protocol.jpeg import read_jpeg_file

WORLDS_CSV = "worlds.csv"


def _world_spans(folder: Path, rows: int) -> list[tuple[int, int]]:
    """Row spans (0-based, end exclusive) of the worlds in ``folder``'s worlds.csv; refuses held-out worlds."""
    path = folder / WORLDS_CSV
    if not path.is_file():
        return [(0, rows)]
    spans = []
    with path.open(encoding="utf-8", newline="") as fh:
        for row in csv.DictReader(fh):
            if row.get("seed_range") not in (None, "", "train"):
                raise BadValue(f"{path}: world {row.get('world_seed')} is an evaluation world "
                               f"({row.get('seed_range')}): a monitor never trains or calibrates on held-out worlds")
            spans.append((int(row["first_row"]) - 1, int(row["last_row"])))
    return spans or [(0, rows)]


def load_runs(folders: list[Path], contract: PreprocessContract, stride: int = 1,
              progress: Callable[[int, int], None] | None = None) -> list[np.ndarray]:
    """Preprocessed centre frames of every run in ``folders`` (every ``stride``-th frame), one array per run."""
    return list(iter_runs(folders, contract, stride, progress))


def iter_runs(folders: list[Path], contract: PreprocessContract, stride: int = 1,
              progress: Callable[[int, int], None] | None = None) -> Iterator[np.ndarray]:
    """:func:`load_runs` one run at a time: a large model input (PilotNet's 66x200 is 160 kB a frame, an hour of
    driving 9 GB) never needs every run in memory at once. The folders are read (and refused) before the first run."""
    plan = []
    for folder in folders:
        folder = Path(folder)
        samples, _ = read_log(find_log(folder))
        if not samples:
            raise BadValue(f"{folder}: no usable rows")
        base = folder if folder.is_dir() else folder.parent
        for first, last in _world_spans(base, len(samples)):
            plan.append(samples[first:last:stride])
    return _read_runs(plan, contract, jpeg_reduction(contract), progress)


def _read_runs(plan: list[list[Sample]], contract: PreprocessContract, reduce: int,
               progress: Callable[[int, int], None] | None) -> Iterator[np.ndarray]:
    total, done = sum(len(p) for p in plan), 0
    for part in plan:
        frames = []
        for sample in part:
            frames.append(preprocess(read_jpeg_file(sample.center, reduce), contract)[0])
            done += 1
            if progress is not None and done % 1000 == 0:
                progress(done, total)
        if frames:
            yield np.stack(frames)
