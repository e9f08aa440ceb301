"""What a model file carries of its misbehaviour monitor: the monitor's graph, its spec and calibrated thresholds.

Why the score runs in its own ONNX Runtime session: a monitor that raises, answers NaN or runs slow must never
touch steering. The monitor's graph travels inside the steering model's file (metadata ``rbc.monitor.onnx``,
base64), with its spec and thresholds (``rbc.monitor``), so one file carries steering, monitor and calibration
and the steering graph itself is byte for byte what it was. A model without them serves exactly as before.
How the server runs it for each client (states, policy, acting on it): :mod:`drive_server.serving.client_monitor`.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import onnxruntime as ort

from protocol.errors import BadValue, UserError

#: ONNX metadata key of the monitor's spec and calibration (JSON, :class:`MonitorSpec`).
MONITOR_KEY = "rbc.monitor"
#: ONNX metadata key of the monitor's own graph (base64 of an ONNX file: preprocessed input -> one score).
MONITOR_GRAPH_KEY = "rbc.monitor.onnx"
#: Frames per second of the Udacity simulator's telemetry: the one-second window's length by default.
FRAMES_PER_SECOND = 15


class MonitorError(UserError):
    """A model file's monitor cannot be used; the message is one line."""

    hint = "attach a monitor with `rbc monitor fit`, or serve with --monitor off"


@dataclass(frozen=True)
class MonitorSpec:
    """What a model file says of its monitor: the score's name, the window and the calibrated thresholds."""

    score: str  # e.g. "autoencoder": the reconstruction error of a small autoencoder (SelfOracle's idea)
    warn: float  # threshold of the window mean for a warning
    alarm: float  # ... and for an alarm (>= warn)
    window: int = FRAMES_PER_SECOND  # frames averaged (one second at the simulator's 15 Hz)
    calibration: dict[str, Any] = field(default_factory=dict)  # how the thresholds were set (data, quantiles)

    def __post_init__(self) -> None:
        if not self.score or not isinstance(self.score, str):
            raise BadValue(f"{MONITOR_KEY}: 'score' must name the score, got {self.score!r}")
        for name in ("warn", "alarm"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value):
                raise BadValue(f"{MONITOR_KEY}: '{name}' must be a finite number, got {value!r}")
        if self.alarm < self.warn:
            raise BadValue(f"{MONITOR_KEY}: the alarm threshold ({self.alarm:g}) is below the warning's "
                           f"({self.warn:g})")
        if not isinstance(self.window, int) or not 1 <= self.window <= 10 * FRAMES_PER_SECOND:
            raise BadValue(f"{MONITOR_KEY}: 'window' must be 1..{10 * FRAMES_PER_SECOND} frames, got {self.window!r}")

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> MonitorSpec:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise BadValue(f"{MONITOR_KEY} is not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise BadValue(f"{MONITOR_KEY} must be a JSON object")
        unknown = set(data) - {"score", "warn", "alarm", "window", "calibration"}
        if unknown:
            raise BadValue(f"{MONITOR_KEY}: unknown keys {sorted(unknown)}")
        try:
            return cls(**data)
        except TypeError as exc:
            raise BadValue(f"{MONITOR_KEY}: {exc}") from None


class MonitorGraph:
    """The monitor's ONNX graph in its own one-thread session: preprocessed input in, one score out."""

    def __init__(self, model_bytes: bytes, name: str = "monitor") -> None:
        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.log_severity_level = 4
        try:
            self._session = ort.InferenceSession(model_bytes, options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # ORT raises several types for a bad graph
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise MonitorError(f"{name}: the monitor's graph cannot be loaded: {first}") from None
        inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        if len(inputs) != 1 or len(outputs) != 1:
            raise MonitorError(f"{name}: the monitor's graph must have one input and one output")
        self.input_name, self.output_name = inputs[0].name, outputs[0].name
        self.model_bytes = model_bytes  # the graph as stored, for a fresh calibration (rbc monitor fit --score keep)

    def score(self, x: np.ndarray) -> float:
        """The score of one preprocessed input batch of 1 (raises whatever ONNX Runtime raises)."""
        out = self._session.run([self.output_name], {self.input_name: x})[0]
        return float(np.asarray(out).reshape(-1)[0])


def read_monitor(meta: dict[str, str], name: str) -> tuple[MonitorSpec, MonitorGraph] | None:
    """The monitor a model file's metadata carries (None: it carries none); MonitorError if it is unusable."""
    if MONITOR_KEY not in meta and MONITOR_GRAPH_KEY not in meta:
        return None
    if MONITOR_KEY not in meta or MONITOR_GRAPH_KEY not in meta:
        raise MonitorError(f"{name}: the monitor needs both {MONITOR_KEY} and {MONITOR_GRAPH_KEY} in the metadata")
    try:
        spec = MonitorSpec.from_json(meta[MONITOR_KEY])
    except BadValue as exc:
        raise MonitorError(f"{name}: {exc}") from None
    try:
        graph_bytes = base64.b64decode(meta[MONITOR_GRAPH_KEY], validate=True)
    except (binascii.Error, ValueError):
        raise MonitorError(f"{name}: {MONITOR_GRAPH_KEY} is not base64") from None
    return spec, MonitorGraph(graph_bytes, name)


def encode_graph(model_bytes: bytes) -> str:
    """The ``rbc.monitor.onnx`` metadata value for a monitor graph."""
    return base64.b64encode(model_bytes).decode("ascii")
