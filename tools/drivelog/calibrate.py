"""Calibrating the camera model on real frames: the side cameras are real views from known offsets.

The left and right frames of a row were taken at the same instant as the centre one, from cameras
displaced sideways. Matching SIFT features on the road between the centre frame and a side frame, the
pitch, the side offset (in camera heights) and a small yaw are fitted so the ground homography of
:mod:`tools.drivelog.camera` maps the side frame's points onto the centre frame's. The same homography
then synthesizes each side view from its centre frame, and the error against the real side frame says
how good the synthesis is (against the error of not moving the camera at all).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from protocol.datalog import Sample
from protocol.errors import BadValue
from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera, ViewSynthesizer, view_homographies

#: Reprojection errors are truncated at this many pixels: a few wrong matches must not steer the fit.
TRUNCATE_PX = 3.0
#: Rows of the frame whose features are matched: the road between the horizon and the bonnet.
ROAD_ROWS = (78, 134)


@dataclass(frozen=True)
class SideFit:
    side: str
    matches: int
    pitch_deg: float
    offset_heights: float  # side camera offset in camera heights (+ right)
    yaw_deg: float
    error_px: float  # mean truncated reprojection error after the fit
    error_unmoved_px: float  # the same with the camera not moved
    view_error: float  # mean |synthesized - real| grey level on the road (blurred), after the fit
    view_error_unmoved: float


def _matches(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    sift, matcher = cv2.SIFT.create(), cv2.BFMatcher()
    mask = np.zeros(a.shape[:2], np.uint8)
    mask[ROAD_ROWS[0]:ROAD_ROWS[1]] = 255
    ka, da = sift.detectAndCompute(a, mask)
    kb, db = sift.detectAndCompute(b, mask)
    if da is None or db is None or len(ka) < 2 or len(kb) < 2:
        return np.zeros((0, 2), np.float32), np.zeros((0, 2), np.float32)
    good = [m[0] for m in matcher.knnMatch(da, db, k=2) if len(m) == 2 and m[0].distance < 0.7 * m[1].distance]
    return (np.array([ka[g.queryIdx].pt for g in good], np.float32).reshape(-1, 2),
            np.array([kb[g.trainIdx].pt for g in good], np.float32).reshape(-1, 2))


def _reprojection(camera: UnityCamera, pairs: Sequence[tuple[np.ndarray, np.ndarray]], pitch: float, offset: float,
                  yaw: float) -> float:
    cam = replace(camera, pitch_deg=pitch, height_m=1.0)
    ground, _ = view_homographies(cam, offset, math.radians(yaw))
    errors = [np.linalg.norm(cv2.perspectiveTransform(side.reshape(-1, 1, 2), ground).reshape(-1, 2) - centre, axis=1)
              for centre, side in pairs if len(side)]
    return float(np.mean(np.minimum(np.concatenate(errors), TRUNCATE_PX))) if errors else math.nan


def _search(f: Callable[[list[float]], float], x: list[float], steps: list[float], rounds: int = 6) -> list[float]:
    """Coordinate search with halving steps: three smooth parameters, no need for an optimiser library."""
    best = f(x)
    for _ in range(rounds):
        for i, step in enumerate(steps):
            for d in (-step, step, -step / 2, step / 2):
                y = list(x)
                y[i] += d
                if (fy := f(y)) < best:
                    x, best = y, fy
        steps = [s / 2 for s in steps]
    return x


def _grey(path: Path) -> np.ndarray:
    return cv2.cvtColor(read_jpeg_file(path), cv2.COLOR_RGB2GRAY)


def fit_side(samples: Sequence[Sample], side: str, camera: UnityCamera = DEFAULT_CAMERA) -> SideFit:
    """Fit pitch, offset and yaw of one side camera on the given rows (which must have side frames)."""
    rows = [s for s in samples if getattr(s, side) is not None]
    if not rows:
        raise BadValue(f"no row has a {side} frame")
    pairs = [_matches(_grey(s.center), _grey(getattr(s, side))) for s in rows]
    sign = -1.0 if side == "left" else 1.0

    def f(x: list[float]) -> float:
        return _reprojection(camera, pairs, *x)

    fits = [_search(f, [p0, sign * 0.5, 0.0], [2.0, 0.2, 1.0]) for p0 in (3.0, 8.0, 14.0)]
    pitch, offset, yaw = min(fits, key=f)
    fitted = replace(camera, pitch_deg=pitch, height_m=1.0)
    return SideFit(side, sum(len(a) for a, _ in pairs), pitch, offset, yaw, f([pitch, offset, yaw]),
                   f([camera.pitch_deg, 0.0, 0.0]), _view_error(rows, side, fitted, offset, yaw),
                   _view_error(rows, side, fitted, 0.0, 0.0))


def _view_error(rows: Sequence[Sample], side: str, camera: UnityCamera, offset: float, yaw: float) -> float:
    synth = ViewSynthesizer(camera)
    top, bottom = ROAD_ROWS
    errors = []
    for s in rows:
        view = synth.view(read_jpeg_file(s.center), offset, math.radians(yaw))
        real = read_jpeg_file(getattr(s, side))
        blur = [cv2.GaussianBlur(cv2.cvtColor(x, cv2.COLOR_RGB2GRAY).astype(np.float32), (0, 0), 2.0)
                for x in (view, real)]
        errors.append(float(np.mean(np.abs(blur[0][top:bottom] - blur[1][top:bottom]))))
    return float(np.mean(errors))


def spread(samples: Sequence[Sample], count: int) -> list[Sample]:
    """``count`` rows evenly spread over the log, away from its first and last frames (standing starts)."""
    with_sides = [s for s in samples if s.has_sides]
    if len(with_sides) <= count:
        return with_sides
    idx = np.linspace(len(with_sides) * 0.05, len(with_sides) * 0.95 - 1, count).astype(int)
    return [with_sides[i] for i in idx]
