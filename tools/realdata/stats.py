"""What a real recording holds, before training on it: the numbers behind ``rbc data stats``.

Everything is read through :func:`protocol.datalog.read_log`, the same reader as training, so the rows
counted here are the rows ``rbc train`` would use. Time comes from the frame names (:mod:`.stamps`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from models.data.labels import centred_average
from models.training.metrics import pearson_r
from protocol.datalog import find_log, read_log
from protocol.stamps import frame_intervals, frame_time, session_ids
from tools.realdata.sharpness import sharpness_values

#: Rows recorded below this speed (the log's unit: mph for the Udacity simulator) count as creeping.
CREEP_SPEED = 5.0
#: The input rule: keyboard when at least KEYBOARD_ZERO_SHARE of the steering values are exactly 0 (between
#: taps the wheel springs back to 0), or when every value lies on a STEER_GRID grid and at least
#: GRID_ZERO_SHARE are 0 (a keyboard stepping the wheel); a mouse or a pad otherwise (smooth, rarely exactly 0).
KEYBOARD_ZERO_SHARE = 0.30
STEER_GRID = 0.05
GRID_ZERO_SHARE = 0.10
#: Frames of the centred average that stands for what the driver meant (``rbc train --smooth-labels``'s
#: default recipe and ``rbc score --smooth-labels``).
INTENT_FRAMES = 9


def steering_input(steering: np.ndarray) -> str:
    """``keyboard`` or ``mouse``, by the rule above."""
    if steering.size == 0:
        return "unknown"
    zero = float(np.mean(steering == 0))
    steps = steering / STEER_GRID
    on_grid = bool(np.all(np.abs(steps - np.round(steps)) < 1e-6))
    return "keyboard" if zero >= KEYBOARD_ZERO_SHARE or (on_grid and zero >= GRID_ZERO_SHARE) else "mouse"


@dataclass
class Measures:
    """The raw material of one recording's stats, or of several (:func:`combine`, for the total)."""

    name: str
    rows: int = 0
    with_sides: int = 0
    missing_images: int = 0
    skipped_rows: int = 0
    undated: int = 0
    sessions: int = 0
    duplicates: int = 0
    steering: np.ndarray = field(default_factory=lambda: np.zeros(0))
    intent: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the steering's INTENT_FRAMES average
    speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    intervals: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sharpness: list[float] = field(default_factory=list)
    inputs: list[str] = field(default_factory=list)  # per recording


@dataclass(frozen=True)
class RecordingStats:
    """One row of ``rbc data stats`` (and one dict of its ``--json``). None: nothing to measure it on."""

    name: str
    rows: int
    rows_with_sides: int
    missing_images: int
    skipped_rows: int
    undated_rows: int
    frame_rate_hz: float | None
    sessions: int
    zero_steer_share: float | None
    input: str
    steer_min: float | None
    steer_max: float | None
    abs_steer_p5: float | None
    abs_steer_p95: float | None
    intent_r: float | None
    speed_min_mph: float | None
    speed_max_mph: float | None
    creep_share: float | None
    duplicates: int
    sharpness: float | None

    def as_dict(self) -> dict:
        return asdict(self)


def intent_r(steering: np.ndarray, intent: np.ndarray) -> float | None:
    """Pearson r of the recorded steering with its centred average (:data:`INTENT_FRAMES`).

    A model that predicted exactly what the driver meant, the average, would score this r against the
    recorded steering: the taps of a keyboard driver around it are noise no picture can predict, so this
    is about the most a model's open-loop r can reach on the recording (None: constant steering).
    """
    r = pearson_r(intent, steering)
    return None if np.isnan(r) else r


def recording_name(path: Path) -> str:
    """A recording's name: its folder's."""
    return find_log(Path(path)).resolve().parent.name


def measure(path: Path, sharpness_frames: int = 20, session_gap_s: float = 1.0) -> Measures:
    """Read one recording and take its measures."""
    samples, report = read_log(path)
    times = [frame_time(s.center.name) for s in samples]
    names = Counter(s.center.name for s in samples)
    steering = np.array([s.steering for s in samples], np.float64)
    centre_missing = sum(1 for s in report.skipped if s.reason.startswith("missing image"))
    side_missing = sum(1 for s in report.side_losses if s.reason.startswith("missing image"))
    return Measures(
        name=recording_name(path), rows=report.rows, with_sides=sum(s.has_sides for s in samples),
        missing_images=centre_missing + side_missing, skipped_rows=len(report.skipped),
        undated=sum(t is None for t in times), sessions=max(session_ids(times, session_gap_s)),
        duplicates=sum(n - 1 for n in names.values()), steering=steering,
        intent=centred_average(steering, INTENT_FRAMES),
        speed=np.array([s.speed for s in samples], np.float64), intervals=frame_intervals(times, session_gap_s),
        sharpness=sharpness_values([s.center for s in samples], sharpness_frames), inputs=[steering_input(steering)])


def combine(measures: Sequence[Measures], name: str = "total") -> Measures:
    """Several recordings' measures as one (sums of the counts, the values pooled)."""
    def pooled(key: str) -> np.ndarray:
        return np.concatenate([getattr(m, key) for m in measures]) if measures else np.zeros(0)

    counts = ("rows", "with_sides", "missing_images", "skipped_rows", "undated", "sessions", "duplicates")
    return Measures(name, **{k: sum(getattr(m, k) for m in measures) for k in counts},
                    steering=pooled("steering"), intent=pooled("intent"), speed=pooled("speed"),
                    intervals=pooled("intervals"),
                    sharpness=[v for m in measures for v in m.sharpness],
                    inputs=[i for m in measures for i in m.inputs])


def summarise(m: Measures) -> RecordingStats:
    """The stats row of one recording's (or the pooled) measures."""
    steer, speed = m.steering, m.speed
    nonzero = np.abs(steer[steer != 0])
    inputs = set(m.inputs)

    def stat(values: np.ndarray, fn) -> float | None:
        return float(fn(values)) if values.size else None

    return RecordingStats(
        name=m.name, rows=m.rows, rows_with_sides=m.with_sides, missing_images=m.missing_images,
        skipped_rows=m.skipped_rows, undated_rows=m.undated,
        frame_rate_hz=stat(m.intervals, lambda v: 1.0 / np.median(v)), sessions=m.sessions,
        zero_steer_share=stat(steer, lambda v: np.mean(v == 0)),
        input=inputs.pop() if len(inputs) == 1 else "mixed" if inputs else "unknown",
        steer_min=stat(steer, np.min), steer_max=stat(steer, np.max),
        abs_steer_p5=stat(nonzero, lambda v: np.percentile(v, 5)),
        abs_steer_p95=stat(nonzero, lambda v: np.percentile(v, 95)),
        intent_r=intent_r(steer, m.intent),
        speed_min_mph=stat(speed, np.min), speed_max_mph=stat(speed, np.max),
        creep_share=stat(speed, lambda v: np.mean(v < CREEP_SPEED)), duplicates=m.duplicates,
        sharpness=float(np.mean(m.sharpness)) if m.sharpness else None)
