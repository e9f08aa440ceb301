"""One recorded frame seen from above, and where the road's edge lines are in it (:mod:`tools.drivelog.road`
puts the frames together).

The frame is looked at from above (the calibrated ground-plane camera, 4-7 m ahead, 5 cm columns),
straightened along the recorded path's curvature. A pixel is road when it has the recording's own
asphalt's colour (the median straight ahead over the whole recording, and its spread, in CIE Lab): its
chroma within 3 spreads and its lightness within 4, each on its own. In each row the road is the run of
road pixels through the car's own column; a run narrower than the car is none, and an edge counts only
where the run stops inside the view. A side's edge is the median over the rows if enough rows saw it and
they agree; a side seen alone counts only where the other side's road ran out of the view.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera, ground_to_pixels

#: Lateral extent and step of the top-down view (m), and the distances ahead it looks at: beyond about 7 m
#: a yellow edge line is a pixel or two wide and JPEG's halved chroma leaves little of it.
VIEW_HALF_WIDTH_M = 8.0
COLUMN_M = 0.05
ROWS_AHEAD_M = tuple(np.arange(4.0, 7.01, 0.5))
#: Straight ahead: where the recording's asphalt colour is learnt (m ahead, m either side).
ASPHALT_AHEAD_M = (4.0, 5.5)
ASPHALT_HALF_WIDTH_M = 0.75
#: A pixel is road within this many robust spreads of the asphalt's chroma (a and b together) and of its
#: lightness, each on its own: sun and shade move the asphalt's lightness across the road by more than they
#: move its colour, while edge lines, dirt, grass, kerbs and water differ in chroma and concrete in lightness.
CHROMA_DISTANCE = 3.0
LIGHTNESS_DISTANCE = 4.0
SPREAD_FLOOR = (8.0, 3.0, 3.0)
#: Of three neighbouring columns (15 cm) the majority decides: a speck does not end the road, a line does.
SMOOTH_COLUMNS = 3
#: A frame's edge needs this many rows that saw it, within this of their median (median absolute deviation,
#: m); a row's run of road must be wider than the car; the road's width must be plausible.
MIN_ROWS = 3
ROW_AGREEMENT_M = 0.5
MIN_RUN_M = 2.0
WIDTH_RANGE_M = (5.0, 14.0)
#: Ground straight ahead counts as asphalt, for telling where the recorded driver left the road, with its
#: chroma within this many spreads: sunlit asphalt is up to 4-5 spreads yellower than the recording's
#: median, the bridge's bricks 3-4 redder and yellower, grass and dirt 7 and more.
OFF_ROAD_CHROMA = 6.0
#: The bridge's bricks are pale and grainy like sunlit asphalt, but redder: the ground straight ahead with
#: its median a* (OpenCV's 8-bit Lab) this much above the asphalt's is not asphalt, and its edges are not
#: measured (the lake's asphalt sits within 1 of its median in 90 % of frames, the bridge 5-7 above).
BRICKS_REDDER = 4.0
#: Shade on the road is learnt only where at least this share of the ground straight ahead, over the
#: recording, is darker than the asphalt's lightness range with about its chroma (jungle: 10-20 %).
SHADE_MIN_SHARE = 0.02
_OUTSIDE = (255, 0, 255)  # magenta: pixels beyond the recorded frame (never asphalt)


@functools.cache
def _outside_lab() -> np.ndarray:
    """:data:`_OUTSIDE` in Lab. Computed on first use, not at import: an OpenCV call at import starts OpenCV's
    thread pool in every process that imports this, and a process forked from one (rbc eval's workers) then
    hangs in its first parallel OpenCV call."""
    return cv2.cvtColor(np.array([[_OUTSIDE]], np.uint8), cv2.COLOR_RGB2LAB)[0, 0].astype(np.float32)


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


@dataclass(frozen=True)
class Asphalt:
    """A recording's asphalt colour in Lab: the median straight ahead and its robust spread, and where the track
    has shade across the road (:attr:`tools.drivelog.track.TrackProfile.shade`) the same of the shaded asphalt."""

    median: np.ndarray
    spread: np.ndarray
    shade: tuple[np.ndarray, np.ndarray] | None = None

    def colours(self) -> list[tuple[np.ndarray, np.ndarray]]:
        return [(self.median, self.spread)] + ([self.shade] if self.shade is not None else [])


def _robust(pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    median = np.median(pixels, axis=0)
    spread = 1.4826 * np.median(np.abs(pixels - median), axis=0)
    return median, np.maximum(spread, SPREAD_FLOOR)


def asphalt_colour(views: list[np.ndarray], shade: bool = False) -> Asphalt:
    """The asphalt's colour straight ahead over many frames; with ``shade``, that of the shaded asphalt too: the
    pixels darker than the asphalt's lightness range with about its chroma (:data:`OFF_ROAD_CHROMA`), if at
    least :data:`SHADE_MIN_SHARE` of them."""
    patch = np.concatenate([_ahead(v).reshape(-1, 3) for v in views]).astype(np.float32)
    median, spread = _robust(patch)
    if not shade:
        return Asphalt(median, spread)
    lab = (patch - median) / spread
    dark = (lab[:, 0] < -LIGHTNESS_DISTANCE) & (np.hypot(lab[:, 1], lab[:, 2]) < OFF_ROAD_CHROMA)
    return Asphalt(median, spread, _robust(patch[dark]) if dark.mean() >= SHADE_MIN_SHARE else None)


def _asphalt(view: np.ndarray, asphalt: Asphalt) -> np.ndarray:
    """Which pixels of a top-down view have the asphalt's colour (chroma and lightness each within theirs), in
    the sun or in the shade."""
    out = np.zeros(view.shape[:2], bool)
    for median, spread in asphalt.colours():
        lab = (view.astype(np.float32) - median) / spread
        out |= (np.abs(lab[..., 0]) < LIGHTNESS_DISTANCE) & (np.hypot(lab[..., 1], lab[..., 2]) < CHROMA_DISTANCE)
    return out


def _asphalt_chroma(view: np.ndarray, asphalt: Asphalt, distance: float) -> np.ndarray:
    """Which pixels have the asphalt's chroma (sunlit or shaded) within ``distance`` spreads, whatever their
    lightness."""
    out = np.zeros(view.shape[:2], bool)
    for median, spread in asphalt.colours():
        lab = (view.astype(np.float32) - median) / spread
        out |= np.hypot(lab[..., 1], lab[..., 2]) < distance
    return out


def _ahead(view: np.ndarray) -> np.ndarray:
    """The ground straight ahead (where the asphalt colour is learnt) of a top-down view."""
    xs, zs = _grid()
    rows = (zs >= ASPHALT_AHEAD_M[0]) & (zs <= ASPHALT_AHEAD_M[1])
    return view[rows][:, np.abs(xs) <= ASPHALT_HALF_WIDTH_M]


def asphalt_ahead(view: np.ndarray, asphalt: Asphalt) -> float:
    """The share of the ground straight ahead with the asphalt's chroma (grass and dirt have not; the
    bridge's bricks and sunlit asphalt, lighter than the asphalt, have)."""
    return float(_asphalt_chroma(_ahead(view), asphalt, OFF_ROAD_CHROMA).mean())


def bricks_ahead(view: np.ndarray, asphalt: Asphalt) -> bool:
    """Whether the ground straight ahead is redder than the asphalt (the bridge's bricks, or dirt)."""
    return float(np.median(_ahead(view)[..., 1])) - float(asphalt.median[1]) >= BRICKS_REDDER


def _close_lines(road: np.ndarray, view: np.ndarray, asphalt: Asphalt, gap_m: float) -> np.ndarray:
    """``road`` with gaps up to ``gap_m`` wide in a row, between road pixels, made road where they have the
    asphalt's chroma whatever their lightness: a white line inside the road (the jungle's dashed centre line)."""
    cols = int(round(gap_m / COLUMN_M)) + 1
    closed = cv2.morphologyEx(road.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((1, cols), np.uint8)) > 0
    return road | (closed & _asphalt_chroma(view, asphalt, CHROMA_DISTANCE))


def frame_edges(view: np.ndarray, asphalt: Asphalt, line_gap_m: float = 0.0) -> tuple[float, float]:
    """(left, right) edge positions of one top-down view (NaN where that side was not seen); ``line_gap_m``: see
    :func:`_close_lines` (0: none)."""
    xs, _ = _grid()
    road = cv2.blur(_asphalt(view, asphalt).astype(np.float32), (SMOOTH_COLUMNS, 1)) > 0.5
    if line_gap_m > 0:
        road = _close_lines(road, view, asphalt, line_gap_m)
    outside = np.all(view == _outside_lab(), axis=-1)
    centre = len(xs) // 2
    lefts: list[float] = []
    rights: list[float] = []
    beyond = [0, 0]  # rows whose road ran out of the view on the left, on the right
    for row, out in zip(road, outside, strict=True):
        if not row[centre]:
            continue
        stops = np.flatnonzero(~row)
        left_stop = stops[stops < centre]
        right_stop = stops[stops > centre]
        if len(left_stop) and len(right_stop) and (right_stop[0] - left_stop[-1]) * COLUMN_M < MIN_RUN_M:
            continue  # narrower than the car: a speck of asphalt-like colour (the bridge's bricks), not a road
        for side, stop, found in ((0, left_stop[-1:], lefts), (1, right_stop[:1], rights)):
            if len(stop) and not out[stop[0]]:
                found.append(xs[stop[0]] + (COLUMN_M / 2 if side == 0 else -COLUMN_M / 2))
            else:
                beyond[side] += 1
    left, right = _agreed(lefts), _agreed(rights)
    # a side seen alone counts only if the road ran out of the view on the other: else that side was
    # unclear (stops scattered over the bricks of the bridge), and so is the frame
    if np.isfinite(left) != np.isfinite(right) and beyond[1 if np.isfinite(left) else 0] < MIN_ROWS:
        return np.nan, np.nan
    if np.isfinite(left) and np.isfinite(right) and not WIDTH_RANGE_M[0] <= right - left <= WIDTH_RANGE_M[1]:
        return np.nan, np.nan
    return left, right


def _agreed(stops: list[float]) -> float:
    """The median of the rows' stops on one side, if enough rows saw it and they agree (NaN otherwise: an
    edge line straightened along the path is one position; stops scattered over metres are texture)."""
    if len(stops) < MIN_ROWS:
        return np.nan
    median = float(np.median(stops))
    return median if np.median(np.abs(np.asarray(stops) - median)) <= ROW_AGREEMENT_M else np.nan
