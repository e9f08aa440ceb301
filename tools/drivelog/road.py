"""Where the road's edges were in each recorded frame, so that a take-over means leaving the road.

DAVE-2 counted a take-over 1 m from the driver's line, on roads whose lanes are barely wider than the car.
The Udacity tracks have no lanes: one road about 9 m between its edge lines, and each driver holds a line
of their own on it, so 1 m from one driver's line is mostly still the middle of the road. Here the road is
found in every recorded centre frame and the car is taken over when its side passes an edge line.

How: the frame is looked at from above (the calibrated ground-plane camera, 4-7 m ahead, 5 cm columns),
straightened along the recorded path's curvature. A pixel is road when it has the recording's own
asphalt's colour (the median straight ahead over the whole recording, and its spread, in CIE Lab): its
chroma within 3 spreads (yellow edge lines, dirt, grass, kerbs and water all differ in chroma) and its
lightness within 4, each on its own (sun and shade move the asphalt's lightness across the road by more
than its colour: a test of both together took sunlit strips for the road's end). In each row the road is
the run of road pixels through the car's own column; a run narrower than the car is none, and an edge
counts only where the run stops inside the view (a run that reaches the view's border says nothing about
that side). A side's edge is the median over the rows if enough rows saw it and they agree; a side seen
alone counts only where the other side's road ran out of the view. Frames whose ground straight ahead is
redder than the asphalt (the bridge's bricks, dirt) are not measured. What is found is where the asphalt
ends, the inner side of the edge line (0.2-0.3 m inside its middle on rendered test frames: the line's
own half width and JPEG's blurred chroma), so the rule errs a little on the strict side. Then over
frames (:func:`_consistent`): edges at least the road's width apart (within 1 m) are kept; where a
frame's edges are closer (a false edge) or it saw one side only, each edge it saw proposes the road's
middle half the road's width away, and the proposal nearest what the frames around propose is kept if it
agrees with them and leaves the recorded car on the road; then a running median over frames, and frames
with nothing believable (the bridge) take the road from their neighbours. Where the recorded driver left
the road (hardly any asphalt straight ahead for 10 frames or more) :attr:`RoadEdges.off_road` says so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from models.data.labels import centred_average
from protocol.camera import CAR_HALF_WIDTH_M
from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera
from tools.drivelog.path import RecordedDrive, curvature, running_median
from tools.drivelog.pitch import ground_pitch
from tools.drivelog.road_view import (
    asphalt_ahead,
    asphalt_colour,
    bricks_ahead,
    frame_edges,
    top_down,
)
from tools.drivelog.track import detect_track, profile

#: Running median over frames (odd).
MEDIAN_FRAMES = 9
#: Frames (evenly spread) whose asphalt colour tells the track where none is given: the asphalt is the same
#: colour all along a recording, and the frames are read again anyway.
DETECT_FRAMES = 200
#: Road width assumed where a recording shows no road at all (m; the lake road between its lines).
DEFAULT_WIDTH_M = 9.0
#: Edge lines found more than this closer together than the recording's road width (m): one of them is false
#: (a sunlit patch of asphalt, a stain ends the run of road pixels mid-road). Also how far a frame's road
#: middle may be from what the frames around it say, where it rests on one edge.
WIDTH_TOLERANCE_M = 1.0
#: The recorded driver is off the road where less than this share of the ground straight ahead has the
#: asphalt's chroma for at least this many frames running (onto the grass, the dirt): no road to keep to.
OFF_ROAD_SHARE = 0.3
OFF_ROAD_FRAMES = 10
#: Frames either side whose edges vote on where the road's middle is, when a frame's own edges disagree.
CONSENSUS_HALF_FRAMES = 15


@dataclass(frozen=True)
class RoadEdges:
    """Per recorded frame: lateral position (m, + right) of the left and right edge lines from where the
    driver's camera was, whether that frame itself showed them (else taken from its neighbours), and
    whether the recorded driver had left the road there."""

    left_m: np.ndarray
    right_m: np.ndarray
    measured: np.ndarray
    width_m: float
    # per frame: the recorded driver was off the road there (OFF_ROAD_SHARE); None: not looked at
    off_road: np.ndarray | None = None
    track: str = "lake"  # the track profile the road was found with (tools.drivelog.track)
    # per frame: the pitch (deg) of the ground ahead the road was seen with (tools.drivelog.pitch); None: the
    # camera's calibrated pitch throughout
    pitch_deg: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.left_m)

    @property
    def measured_share(self) -> float:
        return float(np.mean(self.measured)) if len(self.measured) else 0.0

    def describe(self) -> str:
        """One line: the road's width, how often it was seen, and where the driver kept on it."""
        driver = -(self.left_m + self.right_m) / 2  # the driver from the road's middle, + right
        median = float(np.median(driver))
        off = int(np.sum(self.off_road)) if self.off_road is not None else 0
        return (f"{self.track} road {self.width_m:.1f} m wide between its edges (median), seen in "
                f"{100 * self.measured_share:.0f} % of {len(self)} frames (the others take it from their "
                f"neighbours); the driver {abs(median):.1f} m {'right' if median > 0 else 'left'} of its middle "
                f"(median; 5-95 %: {np.percentile(driver, 5):+.1f} .. {np.percentile(driver, 95):+.1f} m)"
                + (f"; off the road in {off} frames" if off else ""))


def _fill(values: np.ndarray, fallback: float) -> np.ndarray:
    """Gaps filled linearly from their neighbours (ends: the nearest value; nothing at all: ``fallback``)."""
    known = np.flatnonzero(np.isfinite(values))
    if not len(known):
        return np.full(len(values), fallback)
    return np.interp(np.arange(len(values)), known, values[known])


def estimate_road(drive: RecordedDrive, wheelbase_m: float, camera: UnityCamera = DEFAULT_CAMERA,
                  on_frame: Callable[[int, int], None] | None = None, track: str | None = None) -> RoadEdges:
    """The road's edge lines in every centre frame of ``drive`` (one pass over the frames; ``on_frame(done,
    total)`` after each), by the profile of ``track`` (None: the track told from the asphalt's colour)."""
    kappa = curvature(centred_average(drive.steering, 9), wheelbase_m)
    n = len(drive)
    if track is None:  # told from a sample of the frames: the asphalt's colour is the recording's throughout
        sample = np.linspace(0, n - 1, min(n, DETECT_FRAMES)).astype(int)
        track = detect_track(asphalt_colour([top_down(read_jpeg_file(drive.frames[i]), float(kappa[i]), camera)
                                             for i in sample]).median)
    chosen = profile(track, None)
    passes = 2 if chosen.ground_pitch else 1
    pitch = None
    if chosen.ground_pitch:
        pitch = ground_pitch(drive.frames, drive.left_frames, drive.right_frames, drive.session, camera,
                             on_frame=None if on_frame is None else lambda done, _: on_frame(done, passes * n))
    views = []
    for i, path in enumerate(drive.frames):
        seen_by = camera if pitch is None else replace(camera, pitch_deg=float(pitch[i]))
        views.append(top_down(read_jpeg_file(path), float(kappa[i]), seen_by))
        if on_frame:
            on_frame((passes - 1) * n + i + 1, passes * n)
    asphalt = asphalt_colour(views, shade=chosen.shade)
    raw = np.array([(np.nan, np.nan) if bricks_ahead(v, asphalt) else frame_edges(v, asphalt, chosen.line_gap_m)
                    for v in views]).reshape(-1, 2)
    bare = np.array([asphalt_ahead(v, asphalt) < OFF_ROAD_SHARE for v in views], bool)
    both = np.isfinite(raw).all(axis=1)
    width = float(np.median(raw[both, 1] - raw[both, 0])) if both.any() else DEFAULT_WIDTH_M
    measured = np.isfinite(raw).any(axis=1)
    out_left, out_right = np.empty(len(drive)), np.empty(len(drive))
    off_road = np.zeros(len(drive), bool)
    for session in np.unique(drive.session):
        steps = drive.session_range(int(session))
        sl = slice(steps.start, steps.stop)
        left, right = _consistent(raw[sl], width, chosen.consensus_m)
        out_left[sl] = _fill(running_median(left, MEDIAN_FRAMES), -width / 2)
        out_right[sl] = _fill(running_median(right, MEDIAN_FRAMES), width / 2)
        off_road[sl] = _long_runs(bare[sl], OFF_ROAD_FRAMES)
    return RoadEdges(out_left, out_right, measured, width, off_road, chosen.name, pitch)


def _long_runs(flags: np.ndarray, frames: int) -> np.ndarray:
    """``flags`` kept only where they run on for at least ``frames`` frames."""
    out = np.zeros(len(flags), bool)
    start = None
    for i, flag in enumerate([*flags, False]):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            out[start:i] = i - start >= frames
            start = None
    return out


def _consistent(raw: np.ndarray, width: float, consensus_m: float = WIDTH_TOLERANCE_M) -> tuple[np.ndarray, np.ndarray]:
    """Per frame the (left, right) edges from what it saw (``raw``; NaN: not seen), checked against the
    road's width and the frames around it.

    Edges the road's width apart (within ``WIDTH_TOLERANCE_M``) are kept, and so are edges further apart: a
    wider road (the bridge between its walls). Around each frame the road is as wide as the median of the
    kept frames within ``CONSENSUS_HALF_FRAMES`` (the recording's width where there are none). Edges closer
    together than that mean one of them is false (a false edge only ever ends the road early), and a side
    seen alone may be: each seen edge proposes a middle half the road's width from itself, and the
    proposal nearest the median of what the frames around propose wins if it is within the tolerance of
    it (the driver's place on the road changes slowly, a false edge comes and goes); else the frame is
    not believed.
    """
    half = CONSENSUS_HALF_FRAMES
    span = raw[:, 1] - raw[:, 0]
    kept = np.isfinite(span) & (span >= width - WIDTH_TOLERANCE_M)
    local = running_median(np.where(kept, span, np.nan), 2 * half + 1)
    local = np.where(np.isfinite(local), local, width)
    proposals = np.stack([raw[:, 0] + local / 2, raw[:, 1] - local / 2], axis=1)
    left, right = np.where(kept, raw[:, 0], np.nan), np.where(kept, raw[:, 1], np.nan)
    for i in np.flatnonzero(~kept):
        seen = proposals[i][np.isfinite(proposals[i])]
        if not len(seen):
            continue
        consensus = np.nanmedian(proposals[max(0, i - half):i + half + 1])
        middle = seen[np.argmin(np.abs(seen - consensus))]
        lo, hi = middle - local[i] / 2, middle + local[i] / 2
        # believed if it agrees with the frames around and leaves the recorded car on the road: a lone edge
        # further out than that is not the road's (the bridge's wall, with the deck wider than the road)
        if abs(middle - consensus) <= consensus_m and lo < -CAR_HALF_WIDTH_M and hi > CAR_HALF_WIDTH_M:
            left[i], right[i] = lo, hi
    return left, right
