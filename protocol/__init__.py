"""Every shared format and fact: the simulator's wire messages (Socket.IO events ``telemetry`` and
``steer``), THE JPEG decode, the driving-log format, frame size, steering limit, behavior names.

Imports nothing of this project: both ends of the socket (the drive server and the simulator
clients in ``tools``) and the training pipeline share these, so each is defined exactly once.
"""

from protocol.errors import ProtocolError
from protocol.facts import BEHAVIORS, CAMERAS, FRAME_HEIGHT, FRAME_WIDTH, JPEG_QUALITY, MAX_STEERING_DEG
from protocol.jpeg import decode_image, decode_jpeg, encode_image, encode_jpeg
from protocol.messages import (
    SteerCommand,
    Telemetry,
    encode_steer,
    encode_telemetry,
    parse_number,
    parse_steer,
    parse_telemetry,
)
from protocol.units import KMH_PER_MPH, SpeedUnit, to_kmh

__all__ = [
    "BEHAVIORS",
    "CAMERAS",
    "FRAME_HEIGHT",
    "FRAME_WIDTH",
    "JPEG_QUALITY",
    "KMH_PER_MPH",
    "MAX_STEERING_DEG",
    "ProtocolError",
    "SpeedUnit",
    "SteerCommand",
    "Telemetry",
    "decode_image",
    "decode_jpeg",
    "encode_image",
    "encode_jpeg",
    "encode_steer",
    "encode_telemetry",
    "parse_number",
    "parse_steer",
    "parse_telemetry",
    "to_kmh",
]
