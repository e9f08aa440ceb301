"""The misbehaviour monitor as the server runs it for each client: a score per camera frame, averaged over one
second, against thresholds calibrated on nominal driving, so the server can warn, slow down or stop BEFORE the car
leaves the road. What a model file carries of its monitor (spec, graph): :mod:`drive_server.serving.monitor`.

States: ``normal``; ``warning`` once the one-second mean reaches the warning threshold; ``alarm`` once it
reaches the alarm threshold. Either is held until the mean has stayed below the warning threshold for
``release_frames`` frames (the hand-back). With ``--monitor act`` a warning lowers the speed limit of the
coupled control law (the car slows, steering untouched) and an alarm brakes to a stop.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from enum import IntEnum, StrEnum
from time import perf_counter

import numpy as np

from drive_server.serving.monitor import FRAMES_PER_SECOND, MonitorGraph, MonitorSpec
from protocol.errors import BadValue

log = logging.getLogger(__name__)


class MonitorMode(StrEnum):
    """What the server does with the monitor: nothing, report its state, or also act on it."""

    OFF = "off"
    WARN = "warn"
    ACT = "act"


class Level(IntEnum):
    NORMAL = 0
    WARNING = 1
    ALARM = 2

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass(frozen=True)
class MonitorPolicy:
    """How the server uses the monitor. The defaults are defined here once; the CLI's flags read them."""

    # off by default: on the benchmark the best monitor warned a second ahead of under a third of the failures and
    # on real recordings the bundled one of none, and scoring every frame costs time (docs/results.md)
    mode: MonitorMode = MonitorMode.OFF
    slow_factor: float = 0.5  # on a warning (act), the control law's speed limit times this
    release_frames: int = FRAMES_PER_SECOND  # frames below the warning threshold before handing back
    # a monitor slower than this on ``strikes`` of the last second's frames is switched off (a slow
    # monitor must not hold up the simulator); None: no budget, for tools that run on simulated time, where a
    # slow frame delays nobody and a busy machine must not change the figures
    budget_ms: float | None = 5.0
    strikes: int = 12

    def __post_init__(self) -> None:
        if not 0.0 < self.slow_factor <= 1.0:
            raise BadValue(f"monitor slow factor must be above 0 and at most 1, got {self.slow_factor}")
        if self.release_frames < 1:
            raise BadValue(f"monitor release frames must be >= 1, got {self.release_frames}")
        if (self.budget_ms is not None and not self.budget_ms > 0) or not 1 <= self.strikes <= FRAMES_PER_SECOND:
            raise BadValue(f"monitor budget must be > 0 ms (or none) with 1..{FRAMES_PER_SECOND} strikes, got "
                           f"{self.budget_ms} ms, {self.strikes}")


class MonitorFault(RuntimeError):
    """The monitor failed on a frame (raised, answered a non-finite score, or ran over its budget)."""


@dataclass
class MonitorReading:
    """The monitor's view of one frame: its own score, the window mean and the state it leads to."""

    score: float
    mean: float
    level: Level


class MonitorState:
    """One client's monitor: the window of recent scores and the state machine (warning, alarm, hand-back).

    Pure and cheap: a deque and a running sum, so the scripted-score tests drive it without a model.
    """

    def __init__(self, spec: MonitorSpec, policy: MonitorPolicy = MonitorPolicy()) -> None:
        self.spec, self.policy = spec, policy
        self._scores: deque[float] = deque(maxlen=spec.window)
        self._sum = 0.0
        self.level = Level.NORMAL
        self._calm = 0  # frames in a row with the window mean below the warning threshold
        self.counts = {level.label: 0 for level in Level}  # frames per state
        self.episodes = {Level.WARNING.label: 0, Level.ALARM.label: 0}  # entries into each state

    def update(self, score: float) -> MonitorReading:
        if not math.isfinite(score):
            raise MonitorFault(f"monitor score is not finite: {score!r}")
        if len(self._scores) == self._scores.maxlen:
            self._sum -= self._scores[0]
        self._scores.append(score)
        self._sum += score
        mean = self._sum / len(self._scores)
        now = Level.ALARM if mean >= self.spec.alarm else Level.WARNING if mean >= self.spec.warn else Level.NORMAL
        self._calm = self._calm + 1 if now == Level.NORMAL else 0
        if now > self.level:
            self.episodes[now.label] += 1
            self.level = now
        elif self._calm >= self.policy.release_frames:
            self.level = Level.NORMAL  # hand back
        self.counts[self.level.label] += 1
        return MonitorReading(score, mean, self.level)

    def reset(self) -> None:
        self._scores.clear()
        self._sum, self._calm, self.level = 0.0, 0, Level.NORMAL


def at_frame_rate(spec: MonitorSpec, policy: MonitorPolicy, hz: float) -> tuple[MonitorSpec, MonitorPolicy]:
    """``spec`` and ``policy`` for frames at ``hz`` instead of the simulator's 15 Hz: the window and the
    hand-back span as many seconds as they do at 15 Hz (a recording at 9 Hz averages 9 frames, not 15)."""
    if not math.isfinite(hz) or not 1.0 <= hz <= 1000.0:
        raise BadValue(f"frame rate must be 1..1000 Hz, got {hz!r}")

    def frames(n: int) -> int:
        return max(1, round(n * hz / FRAMES_PER_SECOND))

    window = min(frames(spec.window), 10 * FRAMES_PER_SECOND)
    return replace(spec, window=window), replace(policy, release_frames=frames(policy.release_frames))


class ClientMonitor:
    """A client's monitor as the server runs it: scores a frame within the policy's budget, and on any
    failure switches itself off for that client, reported once, leaving steering untouched."""

    def __init__(self, graph: MonitorGraph, spec: MonitorSpec, policy: MonitorPolicy, who: str = "") -> None:
        self.graph, self.state, self.policy, self.who = graph, MonitorState(spec, policy), policy, who
        self.failed: str | None = None  # why it was switched off
        self._slow: deque[bool] = deque(maxlen=FRAMES_PER_SECOND)  # which of the last second's frames ran over
        self.last: MonitorReading | None = None
        self.seconds = 0.0  # time spent in the monitor, for the stage timings

    @property
    def wants_steering(self) -> bool:
        """Its graph takes the served network's steering beside the frame (the spec's ``inputs``)."""
        return self.state.spec.wants_steering

    def observe(self, x: np.ndarray, steering: float | None = None) -> MonitorReading | None:
        """The reading for one preprocessed frame, or None once the monitor is off (never raises). ``steering``:
        the served network's own output for ``x`` (before gain, clamping and smoothing), passed to a graph that
        takes it; such a monitor shown no steering is switched off like any failing one. Callers go through
        :meth:`drive_server.serving.pipeline.DrivePipeline.observe`, which supplies it."""
        if self.failed is not None:
            return None
        t0 = perf_counter()
        before = self.state.level
        try:
            if self.wants_steering:
                if steering is None or not math.isfinite(steering):
                    raise MonitorFault(f"the monitor takes the served steering, got {steering!r}")
                score = self.graph.score(x, steering)
            else:
                score = self.graph.score(x)
            reading = self.state.update(score)
        except Exception as exc:  # a monitor that fails never stops steering: it is switched off
            self._fail(f"{type(exc).__name__}: {exc}"[:200])
            return None
        finally:
            self.seconds = perf_counter() - t0
        budget = self.policy.budget_ms
        if budget is not None:
            self._slow.append(self.seconds * 1000 > budget)
            if sum(self._slow) >= self.policy.strikes:
                self._fail(f"over its budget of {budget:g} ms on {sum(self._slow)} of the last {len(self._slow)} "
                           "frames")
                return None
        self.last = reading
        if reading.level != before:  # at most one line per release_frames frames: the state is held that long
            who = f"client {self.who}: " if self.who else ""
            if reading.level > before:
                log.warning("%smonitor %s: score %.4g over the last second (warning at %.4g, alarm at %.4g)", who,
                            reading.level.label, reading.mean, self.state.spec.warn, self.state.spec.alarm)
            else:
                log.info("%smonitor back to normal: score %.4g", who, reading.mean)
        return reading

    def _fail(self, why: str) -> None:
        self.failed = why
        self.last = None
        log.warning("monitor switched off%s: %s; steering goes on unmonitored",
                    f" for client {self.who}" if self.who else "", why)


def act_on(level: Level, throttle_at: Callable[[float, float, float], float], steering_deg: float, speed_kmh: float,
           policy: MonitorPolicy) -> float:
    """The throttle (-1..1, < 0 brakes) of ``act`` for a state: the control law as is when normal, at a lowered
    speed limit on a warning, full brake while moving on an alarm (0 once stopped: the car waits)."""
    if level == Level.ALARM:
        return -1.0 if speed_kmh > 0.5 else 0.0
    if level == Level.WARNING:
        return throttle_at(steering_deg, speed_kmh, policy.slow_factor)
    return throttle_at(steering_deg, speed_kmh, 1.0)
