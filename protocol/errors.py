"""The one error type raised for malformed wire data."""


class ProtocolError(ValueError):
    """A telemetry or steer message that does not follow the simulator's wire format.

    The message always names the field and what was wrong with it, so a log line is enough
    to diagnose a misbehaving simulator build.
    """
