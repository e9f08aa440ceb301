"""Drive at the pace of the wall clock, so a person can watch a lap (``rbc demo --watch``).

Lock-step mode runs as fast as the machine allows (a 3-minute lap in a few seconds); watching it in the
live view needs simulated time to keep pace with real time. An ``on_frame`` hook that sleeps until the
wall clock has caught up with the frame's simulated time does exactly that, and changes nothing else:
the lap is the same lap, frame for frame.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from protocol.errors import BadValue

if TYPE_CHECKING:
    from tools.sim.driving.scenario import FrameEvent


class WallClockPacer:
    """``on_frame`` hook: wait until ``speed`` x the elapsed wall time has reached the frame's time."""

    def __init__(self, speed: float = 1.0, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if speed <= 0:
            raise BadValue(f"speed must be positive, got {speed}")
        self.speed, self._clock, self._sleep = speed, clock, sleep
        self._start: float | None = None

    def __call__(self, event: FrameEvent) -> None:
        now = self._clock()
        if self._start is None:
            self._start = now - event.t / self.speed
        wait = self._start + event.t / self.speed - now
        if wait > 0:
            self._sleep(wait)


def hooks(*callbacks: Callable[[FrameEvent], None] | None) -> Callable[[FrameEvent], None]:
    """One ``on_frame`` hook calling each given one (``None`` entries are skipped)."""
    chosen: Iterable[Callable[[FrameEvent], None]] = [c for c in callbacks if c is not None]

    def on_frame(event: FrameEvent) -> None:
        for callback in chosen:
            callback(event)

    return on_frame
