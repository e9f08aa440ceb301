"""Who drives the simulated car: a drive server over the Unity wire, an ONNX model in-process, or the autopilot.

Every driver has the same four calls, used by :func:`tools.sim.driving.session.run_scenario`:
``start(scene)`` before a run, ``send(frame)`` for each telemetry frame, ``receive()`` for the reply
to the OLDEST frame not yet answered (FIFO, so two frames can be in flight as with Unity) and
``stop()`` after the run (frames still in flight are dropped). ``close()`` releases resources; a
driver may be reused for many runs.

In-process drivers (:class:`LocalDriver`) only implement ``steer(frame)``: the camera frame as the
base64 JPEG sent on the wire plus the telemetry, to a command. Their replies pass through the same
string encoding as a server's (``encode_steer`` -> ``parse_steer``), so in-process and socket runs
of one model produce the same commands to the last digit.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from drive_server.serving.control import ControlLaw
from protocol import SpeedUnit, SteerCommand, Telemetry, encode_steer, parse_steer, parse_telemetry
from protocol.facts import COLLECT_SPEED_KMH
from tools.sim.track.road import Track
from tools.sim.vehicle.kinematic import VehicleParams, VehicleState

if TYPE_CHECKING:
    from drive_server.serving.client_monitor import MonitorPolicy, MonitorReading
    from tools.sim.driving.autopilot import Autopilot
    from tools.wire.unity_client import UnityWireClient

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Scene:
    """What a run is about; only privileged drivers (the autopilot) look at it."""

    track: Track
    cones: np.ndarray
    direction: int  # +1 default lap direction, -1 reversed
    seed: int
    vehicle: VehicleParams
    control_period_s: float


@dataclass(frozen=True)
class Frame:
    """One telemetry frame: ``payload`` exactly as sent on the wire (strings, base64 JPEG in 'image')."""

    payload: dict[str, str]
    t: float  # simulated seconds
    truth: VehicleState = field(repr=False)  # privileged ground truth (autopilot only)

    @property
    def image_b64(self) -> str:
        return self.payload["image"]

    def telemetry(self) -> Telemetry:
        parsed = parse_telemetry(self.payload)
        assert parsed is not None
        return parsed


@dataclass(frozen=True)
class Reply:
    command: SteerCommand | None  # None: the driver answered 'manual' (keep the previous command)
    latency_s: float  # how long this frame's answer took


class Driver(Protocol):
    name: str

    def start(self, scene: Scene) -> None: ...
    def send(self, frame: Frame) -> None: ...
    def receive(self) -> Reply: ...
    def stop(self) -> None: ...
    def close(self) -> None: ...


class LocalDriver:
    """Base of in-process drivers: queues frames like a socket would and answers them in order."""

    name = "local"

    def __init__(self) -> None:
        self._queue: deque[Frame] = deque()

    def steer(self, frame: Frame) -> SteerCommand:
        raise NotImplementedError

    def start(self, scene: Scene) -> None:
        self._queue.clear()

    def send(self, frame: Frame) -> None:
        self._queue.append(frame)

    def receive(self) -> Reply:
        if not self._queue:
            raise RuntimeError("receive() without a frame in flight")
        frame = self._queue.popleft()
        t0 = time.perf_counter()
        command = parse_steer(encode_steer(self.steer(frame)))  # exactly what a server's reply parses to
        return Reply(command, time.perf_counter() - t0)

    def stop(self) -> None:
        self._queue.clear()

    def close(self) -> None:
        self._queue.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class OnnxDriver(LocalDriver):
    """An ONNX steering model in-process: the drive server's own pipeline (decode, preprocess, infer,
    Eq. 14) without the socket."""

    def __init__(self, model_path: str | Path, law: ControlLaw | None = None,
                 speed_unit: SpeedUnit | str = SpeedUnit.MPH, threads: int = 1,
                 monitor: MonitorPolicy | None = None) -> None:
        from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
        from drive_server.serving.model import InferenceConfig, SteeringModel
        from drive_server.serving.pipeline import DriveConfig, DrivePipeline

        super().__init__()
        model = SteeringModel(Path(model_path), InferenceConfig(threads=threads))
        model.warm_up()
        # a monitor runs without a time budget here: the simulator waits for every frame, so a busy machine must
        # not switch it off and change a run
        policy = replace(monitor, budget_ms=None) if monitor else MonitorPolicy(mode=MonitorMode.OFF)
        self.pipeline = DrivePipeline(model, DriveConfig(law=law or ControlLaw(), speed_unit=SpeedUnit(speed_unit),
                                                         monitor=policy))
        self.smoother = self.pipeline.smoother()  # one driver is one client: smoothed as the model asks
        self.monitor = self.pipeline.client_monitor()  # None: no monitor in the file, or off
        self.readings: list[tuple[float, MonitorReading | None]] = []  # (frame time, reading) with a monitor
        self.name = f"onnx:{Path(model_path).name}"

    def start(self, scene: Scene) -> None:
        super().start(scene)
        self.monitor = self.pipeline.client_monitor()  # each run's monitor starts afresh
        self.smoother = self.pipeline.smoother()  # ... and its smoothing: no steering carried over from a run before
        self.readings = []

    def steer(self, frame: Frame) -> SteerCommand:
        command, _ = self.pipeline.run(frame.telemetry(), self.smoother, self.monitor)
        if self.monitor is not None:
            self.readings.append((frame.t, self.monitor.last))
        return command


class AutopilotDriver(LocalDriver):
    """The scripted keyboard driver of :mod:`tools.sim.driving.autopilot`, fed the ground truth."""

    name = "autopilot"

    def __init__(self, speed_kmh: float = COLLECT_SPEED_KMH, seed: int | None = None) -> None:
        super().__init__()
        self.speed_kmh, self.seed = speed_kmh, seed
        self.autopilot: Autopilot | None = None
        self._period = 0.0

    def start(self, scene: Scene) -> None:
        from dataclasses import replace

        from tools.sim.driving.autopilot import Autopilot, AutopilotParams

        super().start(scene)
        self._period = scene.control_period_s
        self.autopilot = Autopilot(scene.track, scene.direction, scene.cones,
                                   replace(AutopilotParams(), speed_kmh=self.speed_kmh), scene.vehicle,
                                   seed=scene.seed if self.seed is None else self.seed)

    def steer(self, frame: Frame) -> SteerCommand:
        if self.autopilot is None:
            raise RuntimeError("AutopilotDriver.start() was not called")
        return self.autopilot.update(self._period, frame.truth)


class SocketDriver:
    """A drive server over the Unity wire (:class:`tools.wire.unity_client.UnityWireClient`), one connection per run.

    Each run opens a fresh connection, as if the simulator were started anew, so a server's per-client
    state never leaks between scenarios.
    """

    def __init__(self, url: str = "http://127.0.0.1:4567", timeout: float = 10.0) -> None:
        self.url, self.timeout = url, timeout
        self.name = f"socket:{url}"
        self._client: UnityWireClient | None = None
        self._sent: deque[float] = deque()

    def start(self, scene: Scene) -> None:
        from tools.wire.unity_client import UnityWireClient

        self.stop()
        self._client = UnityWireClient(self.url, timeout=self.timeout)
        self._client.connect()

    def send(self, frame: Frame) -> None:
        if self._client is None:
            raise RuntimeError("SocketDriver.start() was not called")
        self._sent.append(time.perf_counter())
        self._client.send_telemetry(frame.payload)

    def receive(self) -> Reply:
        if self._client is None or not self._sent:
            raise RuntimeError("receive() without a frame in flight")
        command = self._client.receive_reply(self.timeout)
        return Reply(command, time.perf_counter() - self._sent.popleft())

    def stop(self) -> None:
        client, self._client = self._client, None
        self._sent.clear()
        if client is not None:
            client.close()

    def close(self) -> None:
        self.stop()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
