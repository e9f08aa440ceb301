"""Logs -> decoded frames -> seeded train/validation split: what training, benchmarks and inspection share."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models.behavior import Pipeline
from models.framecache import FrameCache, build_cache
from models.split import split_indices
from protocol.datalog import DataLogError, DataSet, read_logs

log = logging.getLogger(__name__)


@dataclass
class PreparedData:
    dataset: DataSet
    cache: FrameCache
    usable: np.ndarray  # positions of samples whose frames all decoded
    train: np.ndarray  # cache positions of training samples (log order)
    val: np.ndarray  # cache positions of validation samples (log order)
    steering: np.ndarray  # float32, every sample
    has_sides: np.ndarray  # bool, every sample (False when the pipeline uses no side cameras)


def prepare_data(data: Sequence[Path | str], pipeline: Pipeline, seed: int, val_fraction: float = 0.2,
                 workers: int = 2, progress: Callable[[int, int], None] | None = None) -> PreparedData:
    dataset = read_logs(data)
    cameras = ("center", "left", "right") if pipeline.augment.uses_side_cameras else ("center",)
    cache = build_cache(dataset.samples, pipeline.contract, cameras, workers=workers, progress=progress)
    usable = np.flatnonzero(cache.valid)
    if len(usable) < 2:
        raise DataLogError(f"only {len(usable)} samples with readable frames in {dataset.logs}")
    train, val = split_indices(len(usable), seed, val_fraction)
    steering = np.array([s.steering for s in dataset.samples], np.float32)
    sides = np.array([s.has_sides for s in dataset.samples], bool) & pipeline.augment.uses_side_cameras
    if pipeline.augment.uses_side_cameras and not sides.any():
        log.warning("no sample has left and right frames: perspective shifts are skipped")
    return PreparedData(dataset, cache, usable, usable[train], usable[val], steering, sides)
