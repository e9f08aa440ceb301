"""Frames of a recording for the statistics, and each real frame's nearest headless frame."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from protocol.datalog import read_log
from protocol.errors import BadValue
from tools.realdata.sharpness import evenly_spaced

#: Size of the thumbnails frames are matched by (colour layout, not detail).
THUMB = (32, 16)


def centre_frames(folders: Sequence[Path], count: int) -> list[Path]:
    """``count`` centre frames spread evenly over the given recordings together (in order)."""
    paths: list[Path] = []
    for folder in folders:
        samples, _ = read_log(folder)
        paths += [s.center for s in samples]
    if not paths:
        raise BadValue(f"no readable frames in {', '.join(map(str, folders))}")
    return evenly_spaced(paths, count)


def load_rgb(path: Path) -> np.ndarray | None:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return None if bgr is None else cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def thumbnail(rgb: np.ndarray) -> np.ndarray:
    lab = cv2.cvtColor(cv2.resize(rgb, THUMB, interpolation=cv2.INTER_AREA), cv2.COLOR_RGB2LAB)
    return lab.astype(np.float32).ravel()


def nearest(real: Sequence[np.ndarray], sim: Sequence[np.ndarray]) -> list[tuple[int, float]]:
    """For each real frame, (index of the nearest headless frame, its thumbnail distance per pixel)."""
    s = np.stack([thumbnail(f) for f in sim])
    out = []
    for frame in real:
        d = np.sqrt(((s - thumbnail(frame)) ** 2).sum(axis=1) / (THUMB[0] * THUMB[1]))
        k = int(d.argmin())
        out.append((k, float(d[k])))
    return out
