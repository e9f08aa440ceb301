"""The model's steering smoothed over time, one client at a time: an exponential moving average.

A picture calls for what a driver meant, the mean of their keyboard taps, and a model's answer also
jitters from frame to frame where the picture barely changes. Each frame's command is ``alpha`` of the
model's new output and ``1 - alpha`` of the client's last command; a new client starts from its first
output. ``alpha`` 1 is off. The state is one number per client, so one client never sees another's
steering, and a reconnecting simulator starts afresh.

A model can carry the ``alpha`` it was measured with in its ONNX metadata (``rbc.serving``, written by
a training recipe's ``smoothing``): drive_server and every tool that drives through its pipeline use it unless
told otherwise, so a Unity user who starts ``drive_server`` with no flags gets what was measured. The value has
one name, :data:`NAME`, from the recipe through the model's record and metadata to ``DriveConfig``; files written
before it read under their old names (:data:`OLD_NAMES`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from protocol.errors import BadValue

#: ``alpha`` that leaves every output as it is.
OFF = 1.0
#: ONNX ``metadata_props`` key of how the model is meant to be served: JSON ``{"smoothing": alpha}``.
SERVING_KEY = "rbc.serving"
#: The smoothing's one name: the recipe's ``[export]`` key, the model record's key and ``rbc.serving``'s JSON key.
NAME = "smoothing"
#: What files written before called it: ``rbc.serving``'s JSON key, the model record's key, the recipe's key.
OLD_NAMES = ("smooth", "serve_smooth", "serve_smoothing")


def check_alpha(alpha: float) -> float:
    """``alpha`` if it is a usable weight of the new output (0 < alpha <= 1), else ValueError."""
    if not isinstance(alpha, int | float) or not math.isfinite(alpha) or not 0.0 < alpha <= 1.0:
        raise BadValue(f"steering smoothing must be above 0 and at most 1 (1: off), got {alpha!r}")
    return float(alpha)


def serving_json(alpha: float) -> str:
    """The ``rbc.serving`` metadata value for a model meant to be served with ``alpha``."""
    return json.dumps({NAME: check_alpha(alpha)})


def serving_alpha(text: str | None) -> float:
    """The ``alpha`` a model's ``rbc.serving`` metadata asks for (none: off); ValueError if malformed."""
    if text is None:
        return OFF
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise BadValue(f"{SERVING_KEY} is not valid JSON: {exc}") from None
    if not isinstance(data, dict) or set(data) - {NAME, "smooth"} or len(data) > 1:  # "smooth": before the one name
        raise BadValue(f"{SERVING_KEY} must be a JSON object with at most the key '{NAME}'")
    return check_alpha(data[NAME] if NAME in data else data.get("smooth", OFF))


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
