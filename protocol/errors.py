"""The project's error types: one base whose message and hint are written for a user, and the wire's own.

Every error a user or a client can cause (bad flags, files, tracks, models, telemetry) derives from
:class:`UserError`, so the command line's error boundary prints it as one line with its hint and shows a
traceback only for what is left: bugs. The hint lives on the class (or the instance), never in a table
keyed by class names.
"""


class UserError(Exception):
    """A problem with input a user or a client gave, described in words; ``hint`` says what to do about it."""

    hint: str = ""

    def __init__(self, message: str = "", hint: str | None = None) -> None:
        super().__init__(message)
        if hint is not None:
            self.hint = hint


class BadValue(UserError, ValueError):
    """A value out of range or of the wrong kind (a flag, a config or recipe key, a field of a file)."""


class ProtocolError(BadValue):
    """A telemetry or steer message that does not follow the simulator's wire format.

    The message names the field and what was wrong with it, so a log line is enough to diagnose a
    misbehaving simulator build. ``field`` names it again for code (the wire's key: ``image``, ``speed``,
    ``steering_angle``, ``throttle``, ...; ``""`` when the message as a whole is at fault), so the server
    sorts faults by it, never by the wording of the message.
    """

    field: str = ""

    def __init__(self, message: str = "", hint: str | None = None, *, field: str = "") -> None:
        super().__init__(message, hint)
        self.field = field
