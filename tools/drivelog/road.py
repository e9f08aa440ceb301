"""Where the road's edges were in each recorded frame, so that a take-over means leaving the road.

DAVE-2 counted a take-over 1 m from the driver's line, on roads whose lanes are barely wider than the car.
The Udacity tracks have no lanes: one road about 9 m between its edge lines, and each driver holds a line
of their own on it, so 1 m from one driver's line is mostly still the middle of the road. Here the road is
found in every recorded centre frame and the car is taken over when its side passes an edge line.

How: the frame is looked at from above (the calibrated ground-plane camera, 4-10 m ahead, 5 cm columns),
straightened along the recorded path's curvature; a pixel is road when its colour is the recording's own
asphalt (the median colour straight ahead over the whole recording, and its spread, in CIE Lab: yellow
edge lines, dirt, grass, kerbs and water all differ in chroma); in each row the road is the run of road
pixels through the car's own column, and an edge counts only where that run stops inside the view (a
run that reaches the view's border says nothing about that side). What is found is where the asphalt
ends, the inner side of the edge line (0.2-0.3 m inside its middle on rendered test frames: the line's
own half width and JPEG's blurred chroma), so the rule errs a little on the strict side. Per frame the
median over rows, then a running median over frames; frames that found nothing (the bridge's bricks,
shadows) take the road from their neighbours, a side seen alone takes the recording's median width from
the other.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from models.labels import centred_average
from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera, ground_to_pixels
from tools.drivelog.path import RecordedDrive, curvature

#: Lateral extent and step of the top-down view (m), and the distances ahead it looks at.
VIEW_HALF_WIDTH_M = 8.0
COLUMN_M = 0.05
ROWS_AHEAD_M = tuple(np.arange(4.0, 10.01, 0.5))
#: Straight ahead: where the recording's asphalt colour is learnt (m ahead, m either side).
ASPHALT_AHEAD_M = (4.0, 5.5)
ASPHALT_HALF_WIDTH_M = 0.75
#: A pixel is road within this many robust spreads of the asphalt colour (spreads floored: L, a, b).
ROAD_DISTANCE = 3.0
SPREAD_FLOOR = (8.0, 3.0, 3.0)
#: Runs of road are looked at through a window this wide (m): asphalt grain and specks do not end them.
SMOOTH_M = 0.45
#: A frame's edge needs this many rows that saw it; the road's width must be plausible.
MIN_ROWS = 3
WIDTH_RANGE_M = (5.0, 14.0)
#: Running median over frames (odd).
MEDIAN_FRAMES = 9
#: Road width assumed where a recording shows no road at all (m; the lake road between its lines).
DEFAULT_WIDTH_M = 9.0
_OUTSIDE = (255, 0, 255)  # magenta: pixels beyond the recorded frame (never asphalt)
_OUTSIDE_LAB = cv2.cvtColor(np.uint8([[_OUTSIDE]]), cv2.COLOR_RGB2LAB)[0, 0].astype(np.float32)


@dataclass(frozen=True)
class RoadEdges:
    """Per recorded frame: lateral position (m, + right) of the left and right edge lines from where the
    driver's camera was, and whether that frame itself showed them (else taken from its neighbours)."""

    left_m: np.ndarray
    right_m: np.ndarray
    measured: np.ndarray
    width_m: float

    def __len__(self) -> int:
        return len(self.left_m)

    @property
    def measured_share(self) -> float:
        return float(np.mean(self.measured)) if len(self.measured) else 0.0

    def describe(self) -> str:
        """One line: the road's width, how often it was seen, and where the driver kept on it."""
        driver = -(self.left_m + self.right_m) / 2  # the driver from the road's middle, + right
        median = float(np.median(driver))
        return (f"road {self.width_m:.1f} m wide between its edge lines (median), seen in "
                f"{100 * self.measured_share:.0f} % of {len(self)} frames (the others take it from their "
                f"neighbours); the driver {abs(median):.1f} m {'right' if median > 0 else 'left'} of its middle "
                f"(median; 5-95 %: {np.percentile(driver, 5):+.1f} .. {np.percentile(driver, 95):+.1f} m)")


def _grid() -> tuple[np.ndarray, np.ndarray]:
    """Lateral positions (columns) and distances ahead (rows) of the top-down view, metres."""
    xs = np.arange(-VIEW_HALF_WIDTH_M, VIEW_HALF_WIDTH_M + COLUMN_M / 2, COLUMN_M)
    return xs, np.asarray(ROWS_AHEAD_M)


def top_down(frame: np.ndarray, kappa: float, camera: UnityCamera = DEFAULT_CAMERA) -> np.ndarray:
    """Lab top-down view (rows: distance ahead, columns: lateral; uint8, as OpenCV's 8-bit Lab: a long
    recording's views are kept until the asphalt colour is known), straightened along curvature ``kappa``."""
    xs, zs = _grid()
    x, z = np.meshgrid(xs, zs)
    u, v = ground_to_pixels(camera, x + 0.5 * kappa * z * z, z)
    view = cv2.remap(frame, u.astype(np.float32), v.astype(np.float32), cv2.INTER_AREA,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=_OUTSIDE)
    outside = (u < 0) | (u > camera.width - 1) | (v < 0) | (v > camera.bonnet_row - 1)
    view[outside] = _OUTSIDE
    return cv2.cvtColor(view, cv2.COLOR_RGB2LAB)


def asphalt_colour(views: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(median, robust spread) of the Lab colour straight ahead over many frames."""
    xs, zs = _grid()
    rows = (zs >= ASPHALT_AHEAD_M[0]) & (zs <= ASPHALT_AHEAD_M[1])
    cols = np.abs(xs) <= ASPHALT_HALF_WIDTH_M
    patch = np.concatenate([v[rows][:, cols].reshape(-1, 3) for v in views]).astype(np.float32)
    median = np.median(patch, axis=0)
    spread = 1.4826 * np.median(np.abs(patch - median), axis=0)
    return median, np.maximum(spread, SPREAD_FLOOR)


def frame_edges(view: np.ndarray, median: np.ndarray, spread: np.ndarray) -> tuple[float, float]:
    """(left, right) edge positions of one top-down view (NaN where that side was not seen)."""
    xs, _ = _grid()
    view = view.astype(np.float32)
    distance = np.sqrt((((view - median) / spread) ** 2).sum(-1))
    window = max(1, int(round(SMOOTH_M / COLUMN_M)) | 1)
    road = cv2.blur((distance < ROAD_DISTANCE).astype(np.float32), (window, 1)) > 0.5
    outside = np.all(view == _OUTSIDE_LAB, axis=-1)
    centre = len(xs) // 2
    lefts, rights = [], []
    for row, out in zip(road, outside, strict=True):
        if not row[centre]:
            continue
        stops = np.flatnonzero(~row)
        left_stop = stops[stops < centre]
        right_stop = stops[stops > centre]
        if len(left_stop) and not out[left_stop[-1]]:
            lefts.append(xs[left_stop[-1]] + COLUMN_M / 2)
        if len(right_stop) and not out[right_stop[0]]:
            rights.append(xs[right_stop[0]] - COLUMN_M / 2)
    left = float(np.median(lefts)) if len(lefts) >= MIN_ROWS else np.nan
    right = float(np.median(rights)) if len(rights) >= MIN_ROWS else np.nan
    if np.isfinite(left) and np.isfinite(right) and not WIDTH_RANGE_M[0] <= right - left <= WIDTH_RANGE_M[1]:
        return np.nan, np.nan
    return left, right


def _running_median(values: np.ndarray, frames: int) -> np.ndarray:
    half = frames // 2
    out = np.full(len(values), np.nan)
    for i in range(len(values)):
        window = values[max(0, i - half):i + half + 1]
        if np.isfinite(window).any():
            out[i] = np.nanmedian(window)
    return out


def _fill(values: np.ndarray, fallback: float) -> np.ndarray:
    """Gaps filled linearly from their neighbours (ends: the nearest value; nothing at all: ``fallback``)."""
    known = np.flatnonzero(np.isfinite(values))
    if not len(known):
        return np.full(len(values), fallback)
    return np.interp(np.arange(len(values)), known, values[known])


def estimate_road(drive: RecordedDrive, wheelbase_m: float, camera: UnityCamera = DEFAULT_CAMERA,
                  on_frame: Callable[[int, int], None] | None = None) -> RoadEdges:
    """The road's edge lines in every centre frame of ``drive`` (one pass over the frames; ``on_frame(done,
    total)`` after each)."""
    kappa = curvature(centred_average(drive.steering, 9), wheelbase_m)
    views = []
    for i, path in enumerate(drive.frames):
        views.append(top_down(read_jpeg_file(path), float(kappa[i]), camera))
        if on_frame:
            on_frame(i + 1, len(drive))
    median, spread = asphalt_colour(views)
    raw = np.array([frame_edges(v, median, spread) for v in views]).reshape(-1, 2)
    both = np.isfinite(raw).all(axis=1)
    width = float(np.median(raw[both, 1] - raw[both, 0])) if both.any() else DEFAULT_WIDTH_M
    measured = np.isfinite(raw).any(axis=1)
    left = np.where(np.isfinite(raw[:, 0]), raw[:, 0], raw[:, 1] - width)
    right = np.where(np.isfinite(raw[:, 1]), raw[:, 1], raw[:, 0] + width)
    out_left, out_right = np.empty(len(drive)), np.empty(len(drive))
    for session in np.unique(drive.session):
        steps = drive.session_range(int(session))
        sl = slice(steps.start, steps.stop)
        out_left[sl] = _fill(_running_median(left[sl], MEDIAN_FRAMES), -width / 2)
        out_right[sl] = _fill(_running_median(right[sl], MEDIAN_FRAMES), width / 2)
    return RoadEdges(out_left, out_right, measured, width)
