"""One telemetry frame to one steer command: decode, preprocess, infer, control, with stage timings.

Independent of the socket so the same code serves the simulator, benchmarks and in-process runs.
Preprocessing is whatever the model's contract says, through THE shared ``preprocess`` function.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from time import perf_counter

import numpy as np

from drive_server.serving.client_monitor import (
    ClientMonitor,
    Level,
    MonitorPolicy,
    MonitorReading,
    act_on,
    at_frame_rate,
)
from drive_server.serving.control import ControlLaw
from drive_server.serving.model import SteeringModel
from drive_server.serving.monitor import MonitorGraph, MonitorSpec
from drive_server.serving.preprocess import jpeg_reduction, preprocess
from drive_server.serving.settings import check_gain
from drive_server.serving.smoothing import OFF, SteeringSmoother, check_alpha
from protocol import ProtocolError, SpeedUnit, SteerCommand, Telemetry, decode_image, to_kmh
from protocol.errors import UserError


class InferenceError(UserError, RuntimeError):
    """The model produced something that is not a usable steering value (the model's fault, not ours)."""


@dataclass(frozen=True)
class DriveConfig:
    """The control law (Eq. 14), the unit of the telemetry speed (mph: the stock simulator), the gain on the
    network's steering and the weight of each new output in the per-client smoothing of the steering
    (``drive_server.serving.settings``; None: what the model's metadata asks for, gain 1 and smoothing off for a model
    without)."""

    law: ControlLaw = ControlLaw()
    speed_unit: SpeedUnit = SpeedUnit.MPH
    smoothing: float | None = None
    gain: float | None = None
    monitor: MonitorPolicy = MonitorPolicy()  # what is done with the model's monitor, if it carries one

    def __post_init__(self) -> None:
        if self.smoothing is not None:
            check_alpha(self.smoothing)
        if self.gain is not None:
            check_gain(self.gain)


class DrivePipeline:
    """Stateless per frame (per-client state lives in the server): safe to share between clients."""

    def __init__(self, model: SteeringModel, config: DriveConfig = DriveConfig()) -> None:
        self.model = model
        self.config = config
        self.law = config.law
        self.contract = model.contract
        self.reduce = jpeg_reduction(model.contract)
        self.smoothing = model.smoothing if config.smoothing is None else config.smoothing
        self.gain = model.gain if config.gain is None else config.gain
        self._slow_laws: dict[float, ControlLaw] = {}
        found = model.monitor() if config.monitor.mode != "off" else None
        self.monitor_spec: MonitorSpec | None = found[0] if found is not None else None
        self._monitor_graph: MonitorGraph | None = found[1] if found is not None else None

    def client_monitor(self, who: str = "", frame_rate_hz: float | None = None) -> ClientMonitor | None:
        """A new client's monitor state (None: the model carries no monitor, or it is off). ``frame_rate_hz``:
        frames that come at another rate than the simulator's 15 Hz (a recording): the window and the hand-back
        keep their length in seconds."""
        if self._monitor_graph is None or self.monitor_spec is None:
            return None
        if frame_rate_hz is None:
            return ClientMonitor(self._monitor_graph, self.monitor_spec, self.config.monitor, who)
        spec, policy = at_frame_rate(self.monitor_spec, self.config.monitor, frame_rate_hz)
        return ClientMonitor(self._monitor_graph, spec, policy, who)

    def smoother(self) -> SteeringSmoother | None:
        """A new client's smoothing state (None when off: nothing to keep)."""
        return SteeringSmoother(self.smoothing) if self.smoothing < OFF else None

    def steer(self, rgb: np.ndarray, smoother: SteeringSmoother | None = None,
              monitor: ClientMonitor | None = None) -> float:
        """Normalised steering (-1..1) for one RGB frame (full size or decoded at 1/``reduce``): the network's
        answer times the gain, smoothed by the client's ``smoother`` (:meth:`smoother`) if given; ``monitor``
        scores the same input (``monitor.last``)."""
        x = preprocess(rgb, self.contract)
        value = self.model.predict(x)
        steering = self._usable(value)
        self.observe(monitor, x, value)
        return smoother(steering) if smoother is not None else steering

    def observe(self, monitor: ClientMonitor | None, x: np.ndarray,
                value: float | None = None) -> MonitorReading | None:
        """THE way a preprocessed frame reaches a client's monitor (the server, rbc sim, drive-log, eval, the
        benchmark and the env all come here): its reading, None without a monitor or once it is off. ``value``:
        the network's own output for ``x`` (before gain, clamping and smoothing), for a monitor whose graph takes
        the served steering; run here when the caller has none (the env scores frames an agent steers). Never
        raises: a monitor or a network that fails here switches the monitor off, steering goes on."""
        if monitor is None:
            return None
        if value is None and monitor.wants_steering and monitor.failed is None:
            try:
                value = self.model.predict(x)
            except Exception:  # the monitor reports it (no steering given) and switches itself off
                value = None
        return monitor.observe(x, value)

    def _usable(self, value: float) -> float:
        """The network's output as a steering command: finite, times the serving gain, clamped to -1..1."""
        if not math.isfinite(value):
            raise InferenceError(f"model output is not finite: {value!r}")
        return max(-1.0, min(1.0, value * self.gain))

    def control(self, steering: float, speed: float, reading: MonitorReading | None = None) -> SteerCommand:
        """Eq. 14 on the predicted steering (converted to degrees) and the telemetry speed; with ``--monitor act``
        a monitor's warning lowers the speed limit and its alarm brakes (steering is never changed)."""
        steering_deg, speed_kmh = self.law.steering_deg(steering), to_kmh(speed, self.config.speed_unit)
        if reading is None or self.config.monitor.mode != "act" or reading.level == Level.NORMAL:
            return SteerCommand(steering=steering, throttle=self.law.command(steering_deg, speed_kmh))
        throttle = act_on(reading.level, self._throttle_at, steering_deg, speed_kmh, self.config.monitor)
        return SteerCommand(steering=steering, throttle=throttle)

    def _throttle_at(self, steering_deg: float, speed_kmh: float, factor: float) -> float:
        """Eq. 14 with the speed limit times ``factor`` (the monitor's slow-down)."""
        law = self.law if factor == 1.0 else self._slow_laws.get(factor)
        if law is None:
            law = self._slow_laws[factor] = replace(self.law, speed_limit_kmh=self.law.speed_limit_kmh * factor)
        return law.command(steering_deg, speed_kmh)

    def run(self, telemetry: Telemetry, smoother: SteeringSmoother | None = None,
            monitor: ClientMonitor | None = None) -> tuple[SteerCommand, tuple[float, float, float, float]]:
        """Command for one parsed frame and the durations (s) of decode, preprocess, inference, control.

        ``smoother``: the client's own smoothing state (:meth:`smoother`), applied before the control
        law, so throttle and brake answer the steering that is sent. ``monitor``: the client's monitor
        (:meth:`client_monitor`); it scores the same preprocessed input after steering is known, its reading
        is ``monitor.last``, its time is in the last stage, and a failure of it never reaches steering.

        Raises ``ProtocolError`` for an unusable image and ``InferenceError`` for an unusable output.
        """
        t0 = perf_counter()
        rgb = decode_image(telemetry.image_b64, reduce=self.reduce)
        t1 = perf_counter()
        x = preprocess(rgb, self.contract)
        t2 = perf_counter()
        value = self.model.predict(x)
        t3 = perf_counter()
        steering = self._usable(value)
        reading = self.observe(monitor, x, value)
        command = self.control(smoother(steering) if smoother is not None else steering, telemetry.speed, reading)
        t4 = perf_counter()
        return command, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)


__all__ = ["DriveConfig", "DrivePipeline", "InferenceError", "ProtocolError"]
