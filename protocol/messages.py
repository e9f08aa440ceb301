"""Telemetry and steer messages, parsed and encoded exactly as the Unity simulator does.

The simulator sends every value as a STRING formatted with the machine's locale (``"0,0000"``
happens) and expects strings back with a ``.`` decimal point: a JSON number in a ``steer`` reply
makes it throw silently and stall.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from protocol.errors import ProtocolError


@dataclass(frozen=True, slots=True)
class Telemetry:
    """One telemetry frame. ``image`` stays base64 text until someone needs the pixels."""

    steering_angle_deg: float  # actual wheel angle, degrees (+-25)
    throttle: float  # 0..1
    speed: float  # mph (stock simulator) or km/h (paper's simulator): see SpeedUnit
    image_b64: str


@dataclass(frozen=True, slots=True)
class SteerCommand:
    """What the drive server sends back: steering normalised to -1..1, throttle -1..1 (<0 brakes)."""

    steering: float
    throttle: float


def parse_number(value: object, field: str) -> float:
    """Parse a telemetry number: a string (``"0.25"``, locale ``"0,25"``, ``"7.8E-05"``) or a number.

    Strict on purpose: ASCII decimal only (``float()`` would also take ``"1_000"``, ``"inf"``,
    Arabic-Indic or full-width digits), at most 64 characters, finite, and within sensible bounds
    (speed 0..1000, anything else +-1e6), so that no string can become full throttle or an
    overflow further down.
    """
    low, high = (0.0, 1000.0) if field == "speed" else (-1e6, 1e6)
    if isinstance(value, bool):
        raise ProtocolError(f"{field}: expected a number, got a boolean", field=field)
    if isinstance(value, int):
        if not low <= value <= high:  # compared as int: a 400-digit integer never reaches float()
            raise ProtocolError(f"{field}: {str(value)[:20]}... is outside [{low:g}, {high:g}]", field=field)
        number = float(value)
    elif isinstance(value, float):
        number = value
    elif isinstance(value, str):
        text = value.strip()
        if len(text) > 64:
            raise ProtocolError(f"{field}: number too long ({len(text)} characters)", field=field)
        if "," in text:
            if "." in text:
                raise ProtocolError(f"{field}: ambiguous number {value!r} (both ',' and '.')", field=field)
            text = text.replace(",", ".")
        if not re.fullmatch(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]{1,3})?", text):
            raise ProtocolError(f"{field}: not a number: {value[:40]!r}", field=field)
        number = float(text)
    else:
        raise ProtocolError(f"{field}: expected a number or a string, got {type(value).__name__}", field=field)
    if not math.isfinite(number):
        raise ProtocolError(f"{field}: not finite: {value!r}", field=field)
    if not low <= number <= high:
        raise ProtocolError(f"{field}: {number:g} is outside [{low:g}, {high:g}]", field=field)
    return number


def parse_telemetry(payload: object) -> Telemetry | None:
    """Parse the payload of a ``telemetry`` event; ``None`` means manual mode (a key is held)."""
    if payload is None:
        return None
    if not isinstance(payload, dict):
        raise ProtocolError(f"telemetry: expected a JSON object, got {type(payload).__name__}", field="telemetry")
    missing = [k for k in ("steering_angle", "throttle", "speed", "image") if k not in payload]
    if missing:
        raise ProtocolError(f"telemetry: missing field(s) {', '.join(missing)}", field="telemetry")
    image = payload["image"]
    if not isinstance(image, str) or not image:
        raise ProtocolError("image: expected a non-empty base64 string", field="image")
    return Telemetry(
        steering_angle_deg=parse_number(payload["steering_angle"], "steering_angle"),
        throttle=parse_number(payload["throttle"], "throttle"),
        speed=parse_number(payload["speed"], "speed"),
        image_b64=image,
    )


def _fmt(x: float, digits: int) -> str:
    # repr-free fixed point with '.', never locale dependent, never '-0.0000'
    text = f"{x:.{digits}f}"
    return "0." + "0" * digits if float(text) == 0 else text


def encode_steer(command: SteerCommand) -> dict[str, str]:
    """The ``steer`` payload: both values as strings with a '.' decimal point, clamped to -1..1."""
    for name, v in (("steering", command.steering), ("throttle", command.throttle)):
        if not math.isfinite(v):
            raise ProtocolError(f"{name}: refusing to send a non-finite value {v!r}", field=name)
    steering = min(1.0, max(-1.0, command.steering))
    throttle = min(1.0, max(-1.0, command.throttle))
    return {"steering_angle": _fmt(steering, 6), "throttle": _fmt(throttle, 6)}


def parse_steer(payload: object) -> SteerCommand:
    """Parse a ``steer`` payload (what a simulator client receives)."""
    if not isinstance(payload, dict):
        raise ProtocolError(f"steer: expected a JSON object, got {type(payload).__name__}", field="steer")
    for key in ("steering_angle", "throttle"):
        if key not in payload:
            raise ProtocolError(f"steer: missing field {key}", field=key)
        if not isinstance(payload[key], str):
            raise ProtocolError(f"steer: {key} must be a JSON string (the simulator stalls on numbers)", field=key)
    return SteerCommand(
        steering=parse_number(payload["steering_angle"], "steering_angle"),
        throttle=parse_number(payload["throttle"], "throttle"),
    )


def encode_telemetry(
    steering_angle_deg: float, throttle: float, speed: float, image_b64: str, decimal: str = "."
) -> dict[str, str]:
    """A telemetry payload as Unity writes it (``decimal=','`` imitates a European locale)."""

    def f(x: float) -> str:
        return f"{x:.4f}".replace(".", decimal)

    return {"steering_angle": f(steering_angle_deg), "throttle": f(throttle), "speed": f(speed),
            "image": image_b64}
