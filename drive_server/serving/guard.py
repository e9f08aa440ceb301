"""What to answer when a frame cannot be used: hold the last good command briefly, then stop.

The simulator sends the next frame only after a reply, so a malformed frame must still be answered.
Holding the previous command rides over an isolated glitch (one corrupt JPEG) without a jerk; a run
of bad frames means the input cannot be trusted, so the car is brought to a controlled stop.
"""

from __future__ import annotations

from dataclasses import dataclass

from protocol import SteerCommand
from protocol.errors import BadValue


@dataclass(frozen=True)
class FallbackPolicy:
    """``hold_frames`` bad frames repeat the last good command; after that: steer 0 and brake."""

    hold_frames: int = 3
    stop_throttle: float = -1.0  # full brake; the simulator's brake is progressive, so the stop is smooth

    def __post_init__(self) -> None:
        if self.hold_frames < 0:
            raise BadValue(f"hold_frames must be >= 0, got {self.hold_frames}")
        if not -1.0 <= self.stop_throttle <= 0.0:
            raise BadValue(f"stop_throttle must brake (in [-1, 0]), got {self.stop_throttle}")

    @property
    def stop_command(self) -> SteerCommand:
        return SteerCommand(steering=0.0, throttle=self.stop_throttle)


class FrameGuard:
    """Per-client memory of the last good command and of the current run of bad frames."""

    def __init__(self, policy: FallbackPolicy = FallbackPolicy()) -> None:
        self.policy = policy
        self.last_good: SteerCommand | None = None
        self.bad_run = 0
        self.held = 0  # bad frames answered with the last good command
        self.stopped = 0  # bad frames answered with the stop command

    def good(self, command: SteerCommand) -> SteerCommand:
        self.last_good = command
        self.bad_run = 0
        return command

    def bad(self) -> SteerCommand:
        """The reply to a frame that could not be used."""
        self.bad_run += 1
        if self.last_good is not None and self.bad_run <= self.policy.hold_frames:
            self.held += 1
            return self.last_good
        self.stopped += 1
        return self.policy.stop_command
