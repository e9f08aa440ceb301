"""Thresholds of a monitor from nominal driving only: quantiles of its one-second mean score.

Why quantiles of the window mean and not of single frames: the server compares the one-second mean, so that is
the statistic whose tail sets the false-alarm rate. A threshold at the ``1 - r / F`` quantile, with F one-second
windows per hour of driving (one per frame at 15 Hz), is crossed on about ``r`` frames per hour of nominal
driving like the calibration's, and an episode needs at least one crossing frame, so about ``r`` episodes per
hour at most. A calibration shorter than ``1 / r`` hours cannot show that tail: its maximum is used, and the
record says so.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from drive_server.serving.monitor import FRAMES_PER_SECOND
from protocol.errors import BadValue

FRAMES_PER_HOUR = FRAMES_PER_SECOND * 3600


def window_means(scores: np.ndarray, window: int) -> np.ndarray:
    """The server's one-second mean at every frame of one run (growing windows over its first frames)."""
    scores = np.asarray(scores, dtype=np.float64)
    if scores.size == 0:
        return scores
    csum = np.concatenate([[0.0], np.cumsum(scores)])
    ends = np.arange(1, scores.size + 1)
    starts = np.maximum(0, ends - window)
    return (csum[ends] - csum[starts]) / (ends - starts)


@dataclass(frozen=True)
class Calibration:
    warn: float
    alarm: float
    record: dict  # what the thresholds came from, stored in the model file


def calibrate(runs: Sequence[np.ndarray], window: int, warnings_per_hour: float, alarms_per_hour: float,
              source: str = "") -> Calibration:
    """Thresholds from the per-frame scores of nominal runs (each a sequence in driving order)."""
    if not 0 < alarms_per_hour <= warnings_per_hour:
        raise BadValue(f"expected 0 < alarms per hour <= warnings per hour, got {alarms_per_hour:g} and "
                       f"{warnings_per_hour:g}")
    means = np.concatenate([window_means(r, window) for r in runs if len(r)]) if runs else np.zeros(0)
    if means.size < window:
        raise BadValue(f"calibration needs at least {window} scored frames of nominal driving, got {means.size}")
    hours = means.size / FRAMES_PER_HOUR

    def threshold(per_hour: float) -> tuple[float, bool]:
        q = 1.0 - per_hour / FRAMES_PER_HOUR
        short = means.size * (1.0 - q) < 1.0  # fewer than one frame expected above it: the data has no such tail
        return float(np.max(means) if short else np.quantile(means, q)), short

    warn, warn_short = threshold(warnings_per_hour)
    alarm, alarm_short = threshold(alarms_per_hour)
    record = {"frames": int(means.size), "hours": round(hours, 3), "runs": len(runs), "source": source,
              "warnings_per_hour": warnings_per_hour, "alarms_per_hour": alarms_per_hour,
              "nominal_p50": float(np.median(means)), "nominal_p99": float(np.quantile(means, 0.99)),
              "nominal_max": float(np.max(means)),
              "short": [name for name, short in (("warn", warn_short), ("alarm", alarm_short)) if short]}
    return Calibration(warn, max(alarm, warn), record)
