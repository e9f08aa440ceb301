"""How steep the ground ahead is, frame by frame, read off the side cameras: the pitch of the ground plane.

The ground-plane re-projection (:mod:`tools.drivelog.camera`) and the road finder's view from above
(:mod:`tools.drivelog.road_view`) take the road ahead to be the plane the car stands on, seen 6.2 deg down. On
hills it is not: where the road ahead climbs, its points stand higher than flat ground's and appear nearer
the horizon, so flat ground puts them further away and lateral distances 4-7 m ahead come out 30 % too wide
at 4 deg (too narrow where the road ahead falls away); to the camera such ground is a plane at a larger
pitch than the car's own (a smaller one where it falls away). The left and right cameras see the same
ground from 0.95 m to each side, so the plane's pitch is measured in every frame: the centre frame is
re-projected to each side camera's place for a range of pitches, and the pitch whose views correlate best
with the real side frames (normalised correlation of the road rows) is that frame's. Over frames a running
median removes single misses; frames whose views correlate weakly at every pitch (dark, blurred, a standing
car) keep the calibrated pitch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera, view_homographies
from tools.drivelog.path import running_median

#: Rows of the frame compared (the road between the horizon and the bonnet, as the calibration's).
ROAD_ROWS = (78, 134)
#: Columns compared: the frame's edges are where a re-projected view repeats its border.
ROAD_COLUMNS = (20, 300)
#: Pitches tried (deg): a coarse sweep, then finer steps around the best. The public recordings' hills
#: need -2..16 deg (the calibrated flat-ground pitch is 6.2).
COARSE_DEG = tuple(np.arange(-2.0, 16.01, 2.0))
FINE_STEPS_DEG = (1.0, 0.5)
#: A frame whose best correlation is below this says nothing about its pitch (dark, blurred, no texture).
MIN_CORRELATION = 0.6
#: Running median over frames (odd): the ground's slope changes over metres, a miss in one frame.
MEDIAN_FRAMES = 5
#: Frames are compared at half size: four times faster, and the pitch found within 1 deg of full size's.
SCALE = 0.5
_HALF = np.diag([SCALE, SCALE, 1.0])


def _grey(rgb: np.ndarray) -> np.ndarray:
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
    return cv2.resize(grey, None, fx=SCALE, fy=SCALE, interpolation=cv2.INTER_AREA)


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    top, bottom = (int(r * SCALE) for r in ROAD_ROWS)
    left, right = (int(c * SCALE) for c in ROAD_COLUMNS)
    a, b = a[top:bottom, left:right].ravel(), b[top:bottom, left:right].ravel()
    a, b = a - a.mean(), b - b.mean()
    return float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b) + 1e-9))


def _side_score(centre: np.ndarray, sides: list[tuple[float, np.ndarray]], camera: UnityCamera,
                pitch: float) -> float:
    """Mean correlation of the centre frame re-projected to each side camera with that camera's frame."""
    cam = replace(camera, pitch_deg=pitch)
    h, w = centre.shape
    scores = []
    for lateral, real in sides:
        ground, _ = view_homographies(cam, lateral, 0.0)
        ground = _HALF @ ground @ np.linalg.inv(_HALF)
        view = cv2.warpPerspective(centre, ground, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_REPLICATE)
        scores.append(_ncc(view, real))
    return float(np.mean(scores))


def _best_pitch(grey: np.ndarray, sides: list[tuple[float, np.ndarray]], camera: UnityCamera) -> tuple[float, float]:
    """(pitch, correlation) that re-projects ``grey`` best onto the ``sides`` (lateral offset, grey frame)."""
    scores = {p: _side_score(grey, sides, camera, p) for p in COARSE_DEG}
    best = max(scores, key=scores.__getitem__)
    for step in FINE_STEPS_DEG:
        for p in (best - step, best + step):
            if p not in scores:
                scores[p] = _side_score(grey, sides, camera, p)
        best = max(scores, key=scores.__getitem__)
    return float(best), scores[best]


def frame_pitch(centre: np.ndarray, left: np.ndarray | None, right: np.ndarray | None,
                camera: UnityCamera = DEFAULT_CAMERA) -> tuple[float, float]:
    """(pitch in degrees, its correlation) of the ground ahead in one row's frames (RGB); (NaN, 0) without a
    side frame."""
    sides = [(sign * camera.side_offset_m, _grey(frame)) for sign, frame in ((-1.0, left), (1.0, right))
             if frame is not None]
    if not sides:
        return math.nan, 0.0
    return _best_pitch(_grey(centre), sides, camera)


@dataclass(frozen=True)
class SlopeBin:
    """How well re-projection matches the real side cameras on frames whose ground ahead is this steep."""

    low_deg: float  # |pitch of the ground ahead - the camera's| from this ...
    high_deg: float  # ... to this
    frames: int
    unmoved: float  # correlation of the road rows: the centre frame as it is against a side frame
    flat: float  # ... re-projected 0.95 m sideways over flat ground (the camera's pitch)
    pitched: float  # ... over the ground at the pitch the other side camera measured (held out: not fitted here)


def reprojection_by_slope(frames: Sequence[tuple[Path, Path, Path]], camera: UnityCamera = DEFAULT_CAMERA,
                          edges_deg: Sequence[float] = (0.0, 1.5, 3.5, math.inf)) -> list[SlopeBin]:
    """Each row's (centre, left, right) frames: the centre one re-projected to each side camera's place and
    correlated with its real frame, as it is, over flat ground and over the ground at the pitch measured on the
    other side camera alone; binned by the ground's pitch (both sides measured) off the camera's."""
    per_frame = []
    for centre, left, right in frames:
        grey = _grey(read_jpeg_file(centre))
        sides = [(-camera.side_offset_m, _grey(read_jpeg_file(left))),
                 (camera.side_offset_m, _grey(read_jpeg_file(right)))]
        steep = abs(_best_pitch(grey, sides, camera)[0] - camera.pitch_deg)
        scores = []
        for k, side in enumerate(sides):
            other = _best_pitch(grey, [sides[1 - k]], camera)[0]
            scores.append((_ncc(grey, side[1]), _side_score(grey, [side], camera, camera.pitch_deg),
                           _side_score(grey, [side], camera, other)))
        per_frame.append((steep, *np.mean(scores, axis=0)))
    table = np.array(per_frame).reshape(-1, 4)
    out = []
    for low, high in zip(edges_deg[:-1], edges_deg[1:], strict=True):
        rows = table[(table[:, 0] >= low) & (table[:, 0] < high)]
        if len(rows):
            out.append(SlopeBin(low, high, len(rows), *(float(x) for x in rows[:, 1:].mean(axis=0))))
    return out


def ground_pitch(centre: list[Path], left: list[Path | None] | None, right: list[Path | None] | None,
                 session: np.ndarray, camera: UnityCamera = DEFAULT_CAMERA,
                 on_frame: Callable[[int, int], None] | None = None) -> np.ndarray:
    """Per frame, the pitch (deg) of the ground ahead: measured where the side frames say it (a running median
    over :data:`MEDIAN_FRAMES` within each session), elsewhere the nearest measured frame's, and the calibrated
    pitch where none is."""
    n = len(centre)
    raw = np.full(n, np.nan)
    for i in range(n):
        paths = [None if frames is None else frames[i] for frames in (left, right)]
        sides = [None if path is None else read_jpeg_file(path) for path in paths]
        if any(s is not None for s in sides):
            pitch, score = frame_pitch(read_jpeg_file(centre[i]), sides[0], sides[1], camera=camera)
            raw[i] = pitch if score >= MIN_CORRELATION else np.nan
        if on_frame:
            on_frame(i + 1, n)
    out = np.full(n, camera.pitch_deg)
    for s in np.unique(session):
        idx = np.flatnonzero(session == s)
        smooth = running_median(raw[idx], MEDIAN_FRAMES)
        known = np.flatnonzero(np.isfinite(smooth))
        if len(known):
            out[idx] = np.interp(np.arange(len(idx)), known, smooth[known])
    return out
