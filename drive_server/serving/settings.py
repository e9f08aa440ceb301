"""How a model file asks to be served: its steering gain and its steering smoothing (``rbc.serving``).

A network fitted to the drivers it saw predicts their steering; the closed loop can need more (a hairpin at
full lock) than the drivers' average. That extra strength is a serving setting, not part of the network, so
the open-loop figures (``rbc score``, the cross-validation) are of what the network predicts, and
drive_server, ``rbc drive-log``, ``rbc sim`` and the env apply the same gain the same way:

    command = smooth(clamp(gain * network output, -1, 1))

Both settings have one name from the training recipe's ``[export]`` section through the model's record and
the ``rbc.serving`` metadata to ``DriveConfig`` and drive_server's flags: ``gain`` and ``smoothing``. A file
without ``rbc.serving`` is served as it answers (gain 1, smoothing off). Files written before the gain moved
here carry it inside the graph (their records call it ``output_scale``) and serve exactly as before.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from drive_server.serving.smoothing import NAME as SMOOTHING
from drive_server.serving.smoothing import OFF, check_alpha
from protocol.errors import BadValue

#: ONNX ``metadata_props`` key of how the model is meant to be served: JSON ``{"smoothing": a, "gain": g}``.
SERVING_KEY = "rbc.serving"
#: The gain's one name: the recipe's ``[export]`` key, the model record's key, ``rbc.serving``'s key, the flag.
GAIN = "gain"
#: What recipes called it when it was multiplied into the exported graph.
GAIN_OLD_NAMES = ("output_scale",)
#: The gain that leaves the network's answer as it is.
NO_GAIN = 1.0
#: The gains a model may ask for: beyond 2 every answer above 0.5 is full lock.
GAIN_RANGE = (0.1, 2.0)


def check_gain(gain: float) -> float:
    """``gain`` if it is a usable steering gain (0.1..2), else a one-line ``BadValue``."""
    low, high = GAIN_RANGE
    if isinstance(gain, bool) or not isinstance(gain, int | float) or not math.isfinite(gain) \
            or not low <= gain <= high:
        raise BadValue(f"steering gain must be {low:g}..{high:g} (1: the network's own answer), got {gain!r}")
    return float(gain)


@dataclass(frozen=True)
class Serving:
    """The serving settings a model file asks for (``rbc.serving``); the defaults serve the network as it is."""

    smoothing: float = OFF
    gain: float = NO_GAIN

    def __post_init__(self) -> None:
        check_alpha(self.smoothing)
        check_gain(self.gain)

    def to_json(self) -> str:
        """The ``rbc.serving`` value; only the settings that differ from the default (a reader written before the
        gain existed still reads a file that asks for none)."""
        data = {k: v for k, v in ((SMOOTHING, self.smoothing), (GAIN, self.gain))
                if v != (OFF if k == SMOOTHING else NO_GAIN)}
        return json.dumps(data, sort_keys=True)

    @property
    def asks_anything(self) -> bool:
        return self != Serving()

    def describe(self) -> str:
        """``steering x1.5, smoothed (alpha 0.5)``; empty when nothing is asked."""
        parts = ([f"steering x{self.gain:g}"] if self.gain != NO_GAIN else []) \
            + ([f"smoothed (alpha {self.smoothing:g})"] if self.smoothing < OFF else [])
        return ", ".join(parts)

    @classmethod
    def from_json(cls, text: str | None) -> Serving:
        """What ``rbc.serving`` asks for (None: nothing); a one-line ``BadValue`` if it is malformed."""
        if text is None:
            return cls()
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise BadValue(f"{SERVING_KEY} is not valid JSON: {exc}") from None
        known = {SMOOTHING, "smooth", GAIN}  # "smooth": the smoothing's name before it had one
        if not isinstance(data, dict) or set(data) - known or {SMOOTHING, "smooth"} <= set(data):
            raise BadValue(f"{SERVING_KEY} must be a JSON object with at most the keys '{SMOOTHING}' and '{GAIN}'")
        smoothing = data[SMOOTHING] if SMOOTHING in data else data.get("smooth", OFF)
        return cls(smoothing=check_alpha(smoothing),
                   gain=check_gain(data.get(GAIN, NO_GAIN)))


def serving_json(smoothing: float = OFF, gain: float = NO_GAIN) -> str:
    """The ``rbc.serving`` metadata value for a model meant to be served with ``smoothing`` and ``gain``."""
    return Serving(smoothing, gain).to_json()


def serving_alpha(text: str | None) -> float:
    """The smoothing a model's ``rbc.serving`` metadata asks for (none: off); ``BadValue`` if malformed."""
    return Serving.from_json(text).smoothing

