"""Wire format of the Udacity/Unity driving simulator (Socket.IO events ``telemetry`` and ``steer``).

Imports nothing of this project: both ends of the socket (the drive server and the simulator
clients in ``tools``) share these types so the format is defined exactly once.
"""

from protocol.errors import ProtocolError
from protocol.messages import (
    FRAME_HEIGHT,
    FRAME_WIDTH,
    MAX_STEERING_DEG,
    SteerCommand,
    Telemetry,
    decode_image,
    encode_image,
    encode_steer,
    encode_telemetry,
    parse_number,
    parse_steer,
    parse_telemetry,
)
from protocol.units import KMH_PER_MPH, SpeedUnit, to_kmh

__all__ = [
    "FRAME_HEIGHT",
    "FRAME_WIDTH",
    "KMH_PER_MPH",
    "MAX_STEERING_DEG",
    "ProtocolError",
    "SpeedUnit",
    "SteerCommand",
    "Telemetry",
    "decode_image",
    "encode_image",
    "encode_steer",
    "encode_telemetry",
    "parse_number",
    "parse_steer",
    "parse_telemetry",
    "to_kmh",
]
