"""The model's steering smoothed over time, one client at a time: an exponential moving average.

A picture calls for what a driver meant, the mean of their keyboard taps, and a model's answer also
jitters from frame to frame where the picture barely changes. Each frame's command is ``alpha`` of the
model's new output and ``1 - alpha`` of the client's last command; a new client starts from its first
output. ``alpha`` 1 is off. The state is one number per client, so one client never sees another's
steering, and a reconnecting simulator starts afresh.

A model can carry the ``alpha`` it was measured with in its ONNX metadata (``rbc.serving``,
``drive_server.serving.settings``, written by a training recipe's ``smoothing``): drive_server and every tool that
drives through its pipeline use it unless told otherwise, so a Unity user who starts ``drive_server`` with no
flags gets what was measured. The value has one name, :data:`NAME`, from the recipe through the model's record
and metadata to ``DriveConfig``; files written before it read under their old names (:data:`OLD_NAMES`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from protocol.errors import BadValue

#: ``alpha`` that leaves every output as it is.
OFF = 1.0
#: The smoothing's one name: the recipe's ``[export]`` key, the model record's key and ``rbc.serving``'s JSON key.
NAME = "smoothing"
#: What files written before called it: ``rbc.serving``'s JSON key, the model record's key, the recipe's key.
OLD_NAMES = ("smooth", "serve_smooth", "serve_smoothing")


def check_alpha(alpha: float) -> float:
    """``alpha`` if it is a usable weight of the new output (0 < alpha <= 1), else ValueError."""
    if not isinstance(alpha, int | float) or not math.isfinite(alpha) or not 0.0 < alpha <= 1.0:
        raise BadValue(f"steering smoothing must be above 0 and at most 1 (1: off), got {alpha!r}")
    return float(alpha)


@dataclass
class SteeringSmoother:
    """``smoother(value)``: the smoothed steering; only finite values reach it (the pipeline checks them)."""

    alpha: float = OFF
    last: float | None = None

    def __post_init__(self) -> None:
        check_alpha(self.alpha)

    def __call__(self, value: float) -> float:
        self.last = value if self.last is None else self.alpha * value + (1.0 - self.alpha) * self.last
        return self.last
