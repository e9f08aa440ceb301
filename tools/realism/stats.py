"""Image statistics of camera frames, per horizontal band, and the gap between two sets of frames.

The bands are data (:data:`BANDS`): rows of the 320x160 frame where the real simulator's camera shows
sky, the horizon, far and near road and the car's bonnet (horizon near row 64, bonnet from row 137,
as measured on the real lake frames; see :mod:`protocol.camera`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from protocol.camera import BONNET_ROW

#: (name, first row, end row) of each band of a 320x160 frame.
BANDS: tuple[tuple[str, int, int], ...] = (
    ("sky", 0, 50), ("horizon", 50, 72), ("far_road", 72, 100), ("near_road", 100, BONNET_ROW),
    ("bonnet", BONNET_ROW, 160))
#: Per band: mean red, green, blue, brightness (grey mean), contrast (grey std), colourfulness (mean HSV
#: saturation), edge density (share of Canny edge pixels) and sharpness (log10 of the Laplacian's variance).
MEASURES: tuple[str, ...] = ("red", "green", "blue", "brightness", "contrast", "saturation", "edges", "sharpness")
#: Canny thresholds (grey levels) of the edge density.
CANNY = (80, 160)


def frame_stats(rgb: np.ndarray) -> dict[str, float]:
    """``{"band.measure": value}`` of one RGB frame (any size; bands are scaled to its height)."""
    scale = rgb.shape[0] / 160
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    sat = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)[..., 1]
    edges = cv2.Canny(grey, *CANNY)
    lap = cv2.Laplacian(grey, cv2.CV_64F)
    out: dict[str, float] = {}
    for name, top, bottom in BANDS:
        rows = slice(round(top * scale), round(bottom * scale))
        band = rgb[rows].reshape(-1, 3).astype(np.float64)
        g = grey[rows].astype(np.float64)
        out[f"{name}.red"], out[f"{name}.green"], out[f"{name}.blue"] = (float(v) for v in band.mean(axis=0))
        out[f"{name}.brightness"] = float(g.mean())
        out[f"{name}.contrast"] = float(g.std())
        out[f"{name}.saturation"] = float(sat[rows].mean())
        out[f"{name}.edges"] = float((edges[rows] > 0).mean())
        out[f"{name}.sharpness"] = float(np.log10(lap[rows].var() + 1.0))
    return out


def keys() -> list[str]:
    return [f"{band}.{measure}" for band, _, _ in BANDS for measure in MEASURES]


@dataclass(frozen=True)
class Gap:
    """One statistic of two sets of frames: means, spreads, and the difference in real spreads."""

    key: str
    real_mean: float
    real_std: float
    sim_mean: float
    sim_std: float

    @property
    def standardized(self) -> float:
        """(sim - real) / the real frames' spread (an effect size: 0 = same, 1 = one spread apart)."""
        return (self.sim_mean - self.real_mean) / max(self.real_std, 1e-6)


def gaps(real: Sequence[dict[str, float]], sim: Sequence[dict[str, float]]) -> list[Gap]:
    out = []
    for key in keys():
        r = np.array([s[key] for s in real])
        m = np.array([s[key] for s in sim])
        out.append(Gap(key, float(r.mean()), float(r.std()), float(m.mean()), float(m.std())))
    return out


def overall_gap(found: Sequence[Gap]) -> float:
    """Median absolute standardized difference over every statistic (one number for the README)."""
    return float(np.median([abs(g.standardized) for g in found]))
