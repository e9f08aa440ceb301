"""How sharp a recording's frames are: the variance of the Laplacian of grey frames.

Low values mean blur or a low graphics setting (few edges); the figure compares recordings, it is not an
absolute quality. A few evenly spaced frames are enough, so stats on a large recording stay quick.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np


def laplacian_variance(path: Path) -> float | None:
    """Variance of the Laplacian of the frame in grey, None if it cannot be decoded."""
    grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if grey is None:
        return None
    return float(cv2.Laplacian(grey, cv2.CV_64F).var())


def evenly_spaced(items: Sequence[Path], count: int) -> list[Path]:
    """``count`` items spread over the whole sequence, first and last included (all of them if fewer)."""
    if count <= 0 or not items:
        return []
    if count >= len(items):
        return list(items)
    return [items[i] for i in np.linspace(0, len(items) - 1, count).round().astype(int)]


def sharpness_values(frames: Sequence[Path], count: int) -> list[float]:
    """Laplacian variance of ``count`` evenly spaced frames (undecodable ones left out)."""
    values = (laplacian_variance(p) for p in evenly_spaced(frames, count))
    return [v for v in values if v is not None]
