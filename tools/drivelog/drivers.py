"""Who drives the closed loop: a model through drive_server's own pipeline, or a baseline that tests the measure.

``recorded`` steers as the person did and must stay on the path (the measure's sanity check); ``zero``
never steers and must fail on the curves; ``--steer-bias`` shifts any of them and must make it fail.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from protocol.errors import BadValue
from tools.drivelog.loop import Driver
from tools.drivelog.path import RecordedDrive


def recording_rate_hz(log: RecordedDrive) -> float:
    """The recording's frame rate: the median interval between its frames (15 Hz when it has too few)."""
    gaps = log.dt[np.isfinite(log.dt) & (log.dt > 0)]
    return float(np.clip(1.0 / np.median(gaps), 1.0, 1000.0)) if len(gaps) else 15.0


def make_driver(log: RecordedDrive, model: Path | None, baseline: str | None, bias: float = 0.0,
                smooth: float | None = None, readings: list[tuple[int, int]] | None = None,
                gain: float | None = None) -> tuple[Driver, str]:
    """(driver, its name for the record). Exactly one of ``model`` and ``baseline`` is given.

    The model's steering is multiplied by the gain and smoothed over the drive as drive_server does for a
    client: by ``gain`` and ``smooth``, or (None) as the model's metadata asks. A model carrying a misbehaviour
    monitor is monitored as drive_server's ``--monitor warn`` does: each view's (frame index, state) is appended
    to ``readings`` if given.
    """
    if model is not None:
        from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
        from drive_server.serving.model import SteeringModel
        from drive_server.serving.pipeline import DriveConfig, DrivePipeline

        # the monitor as --monitor warn, without a time budget: the loop runs on the log's clock, so a busy
        # machine must not switch it off and change the figures
        pipeline = DrivePipeline(SteeringModel(Path(model)),
                                 DriveConfig(smoothing=smooth, gain=gain,
                                             monitor=MonitorPolicy(MonitorMode.WARN, budget_ms=None)))
        smoother = pipeline.smoother()
        # the model's misbehaviour monitor, if its file carries one (warn), its one-second window at the log's rate
        monitor = pipeline.client_monitor(frame_rate_hz=recording_rate_hz(log))

        def base(view: np.ndarray, i: int) -> float:
            steering = pipeline.steer(view, smoother, monitor)
            if monitor is not None and readings is not None:
                reading = monitor.last
                readings.append((i, int(reading.level) if reading is not None else 0))
            return steering

        name = Path(model).name + (f" gain {pipeline.gain:g}" if pipeline.gain != 1.0 else "") \
            + (f" smoothed {pipeline.smoothing:g}" if smoother is not None else "")
    elif baseline == "recorded":
        def base(view: np.ndarray, i: int) -> float:
            return float(log.steering[i])

        name = "recorded steering"
    elif baseline == "zero":
        def base(view: np.ndarray, i: int) -> float:
            return 0.0

        name = "always 0"
    else:
        raise BadValue(f"unknown baseline {baseline!r}", "give a model, or the baseline recorded or zero")
    if not bias:
        return base, name

    def biased(view: np.ndarray, i: int) -> float:
        return float(np.clip(base(view, i) + bias, -1.0, 1.0))

    return biased, f"{name} {bias:+g}"
