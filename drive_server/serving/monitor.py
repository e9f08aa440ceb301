"""What a model file carries of its misbehaviour monitor: the monitor's graph, its spec and calibrated thresholds.

Why the score runs in its own ONNX Runtime session: a monitor that raises, answers NaN or runs slow must never
touch steering. The monitor's graph travels inside the steering model's file (metadata ``rbc.monitor.onnx``,
base64), with its spec and thresholds (``rbc.monitor``), so one file carries steering, monitor and calibration
and the steering graph itself is byte for byte what it was. A model without them serves exactly as before. The
graph takes the preprocessed frame, and where the spec's ``inputs`` say so the served network's steering for it
(the ``ensemble`` score: the served network against other networks trained to the same recipe).
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
#: ONNX metadata key of the monitor's own graph (base64 of an ONNX file: its inputs -> one score).
MONITOR_GRAPH_KEY = "rbc.monitor.onnx"
#: What a monitor's graph takes, in the order of its inputs: the steering model's preprocessed frame (always), and
#: for some scores the served network's steering for that frame, float32 of shape (batch, 1): the network's own
#: output, before the serving gain, the clamping to -1..1 and the smoothing (so a score compares networks, not
#: serving settings).
FRAME, STEERING = "frame", "steering"
#: The input lists a spec may name (``MonitorSpec.inputs``).
GRAPH_INPUTS: tuple[tuple[str, ...], ...] = ((FRAME,), (FRAME, STEERING))
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
    inputs: tuple[str, ...] = (FRAME,)  # what the graph takes (GRAPH_INPUTS); left out of the JSON when the frame only

    def __post_init__(self) -> None:
        if isinstance(self.inputs, list):  # as read from JSON
            object.__setattr__(self, "inputs", tuple(self.inputs))
        if self.inputs not in GRAPH_INPUTS:
            choices = " or ".join(json.dumps(list(i)) for i in GRAPH_INPUTS)
            raise BadValue(f"{MONITOR_KEY}: 'inputs' must be {choices}, got {json.dumps(self.inputs)}")
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

    @property
    def wants_steering(self) -> bool:
        """The graph takes the served network's steering beside the frame."""
        return STEERING in self.inputs

    def to_json(self) -> str:
        data = asdict(self)
        if self.inputs == (FRAME,):  # a frame-only monitor reads as it did before specs named their inputs
            del data["inputs"]
        return json.dumps(data, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> MonitorSpec:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise BadValue(f"{MONITOR_KEY} is not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise BadValue(f"{MONITOR_KEY} must be a JSON object")
        unknown = set(data) - {"score", "warn", "alarm", "window", "calibration", "inputs"}
        if unknown:
            raise BadValue(f"{MONITOR_KEY}: unknown keys {sorted(unknown)}")
        try:
            return cls(**data)
        except TypeError as exc:
            raise BadValue(f"{MONITOR_KEY}: {exc}") from None


class MonitorGraph:
    """The monitor's ONNX graph in its own one-thread session: the preprocessed frame (and, if its spec says so, the
    served network's steering) in, one score out."""

    def __init__(self, model_bytes: bytes, name: str = "monitor", inputs: tuple[str, ...] = (FRAME,)) -> None:
        names = tuple(inputs)  # what the spec says the graph takes (GRAPH_INPUTS), in its inputs' order
        options = ort.SessionOptions()
        options.intra_op_num_threads = options.inter_op_num_threads = 1
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.log_severity_level = 4
        try:
            self._session = ort.InferenceSession(model_bytes, options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # ORT raises several types for a bad graph
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise MonitorError(f"{name}: the monitor's graph cannot be loaded: {first}") from None
        fed, outputs = self._session.get_inputs(), self._session.get_outputs()
        if len(fed) != len(names) or len(outputs) != 1:
            raise MonitorError(f"{name}: the monitor's graph must have {len(names)} input(s) ({', '.join(names)}) and "
                               f"one output, it has {len(fed)} and {len(outputs)}")
        self.inputs = names
        self.input_name, self.output_name = fed[0].name, outputs[0].name
        self.steering_name: str | None = fed[1].name if len(fed) > 1 else None
        self.model_bytes = model_bytes  # the graph as stored, for a fresh calibration (rbc monitor fit --score keep)

    @property
    def wants_steering(self) -> bool:
        return self.steering_name is not None

    def score(self, x: np.ndarray, steering: float | None = None) -> float:
        """The score of one preprocessed input batch of 1; ``steering``: the served network's own output for it,
        which a graph that takes it needs (raises ValueError without it, else whatever ONNX Runtime raises)."""
        feed = {self.input_name: x}
        if self.steering_name is not None:
            if steering is None:
                raise ValueError("the monitor's graph takes the served steering, and none was given")
            feed[self.steering_name] = np.full((len(x), 1), steering, np.float32)
        out = self._session.run([self.output_name], feed)[0]
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
    return spec, MonitorGraph(graph_bytes, name, spec.inputs)


def encode_graph(model_bytes: bytes) -> str:
    """The ``rbc.monitor.onnx`` metadata value for a monitor graph."""
    return base64.b64encode(model_bytes).decode("ascii")
