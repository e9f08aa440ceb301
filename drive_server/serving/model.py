"""The steering network behind ONNX Runtime, validated before the server starts listening.

Every way a model file can be unusable (missing, not ONNX, wrong input rank or shape, several outputs,
a contract that does not match the input) becomes a ``ModelError`` with a one-line message, so the
CLI can refuse to start instead of failing on the simulator's first frame.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnxruntime as ort

from drive_server.serving.contract import METADATA_KEY, ContractError, PreprocessContract, infer_contract
from drive_server.serving.monitor import MonitorGraph, MonitorSpec, read_monitor
from drive_server.serving.settings import SERVING_KEY, Serving
from protocol.errors import BadValue, UserError

log = logging.getLogger(__name__)


class ModelError(UserError):
    """The model file cannot be served; the message is one line meant for the user."""

    hint = "pass an .onnx model exported by rbc train, or a bundled one from models/pretrained/"


@dataclass(frozen=True)
class InferenceConfig:
    """ONNX Runtime settings. One thread by default: a 14k-parameter CNN gains nothing from more,
    and the simulator shares the machine."""

    threads: int = 1
    provider: str = "CPUExecutionProvider"

    def __post_init__(self) -> None:
        if self.threads < 1:
            raise BadValue(f"threads must be >= 1, got {self.threads}")


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _session_options(config: InferenceConfig) -> ort.SessionOptions:
    so = ort.SessionOptions()
    so.intra_op_num_threads = config.threads
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.log_severity_level = 4  # errors reach the user as ModelError, not as ORT's multi-line log
    return so


class SteeringModel:
    """An ONNX steering model: one float32 image input of rank 4, one output holding one value."""

    def __init__(self, path: Path, config: InferenceConfig = InferenceConfig()) -> None:
        path = Path(path)
        if not path.is_file():
            raise ModelError(f"model file not found: {path}")
        available = ort.get_available_providers()
        if config.provider not in available:
            raise ModelError(f"execution provider {config.provider!r} is not available (have: {', '.join(available)})")
        try:
            self._session = ort.InferenceSession(str(path), _session_options(config), providers=[config.provider])
        except Exception as exc:  # ORT raises several types (Fail, InvalidGraph, InvalidProtobuf, ...)
            raise ModelError(f"cannot load {path} as an ONNX model: {_first_line(exc)}") from None
        self.path = path
        self.config = config
        inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        if len(inputs) != 1:
            raise ModelError(f"{path.name}: expected exactly one input, the model has {len(inputs)}")
        if len(outputs) != 1:
            raise ModelError(f"{path.name}: expected exactly one output (steering), the model has {len(outputs)}")
        inp = inputs[0]
        if inp.type != "tensor(float)":
            raise ModelError(f"{path.name}: input {inp.name!r} must be float32, not {inp.type}")
        if len(inp.shape) != 4:
            raise ModelError(f"{path.name}: model input must have rank 4 (N,H,W,C or N,C,H,W), "
                             f"got shape {list(inp.shape)}")
        static = [d for d in outputs[0].shape if isinstance(d, int)]
        if int(np.prod(static)) > 1:
            raise ModelError(f"{path.name}: output must hold one steering value, got shape {list(outputs[0].shape)}")
        self.input_name, self.output_name = inp.name, outputs[0].name
        self.input_shape = tuple(inp.shape)
        self.contract, self.contract_source = self._contract()
        try:  # the steering gain and smoothing the model was measured with (drive_server.serving.settings)
            self.serving = Serving.from_json(self._session.get_modelmeta().custom_metadata_map.get(SERVING_KEY))
        except ValueError as exc:
            raise ModelError(f"{path.name}: {exc}") from None
        self.smoothing, self.gain = self.serving.smoothing, self.serving.gain
        self._outputs = [self.output_name]
        self._monitor: tuple[MonitorSpec, MonitorGraph] | None = None
        self._monitor_read = False

    def monitor(self) -> tuple[MonitorSpec, MonitorGraph] | None:
        """The misbehaviour monitor the file carries (None: none); read on first use, so a model whose monitor
        is broken still serves with ``--monitor off``. Raises ``MonitorError`` (one line) if it is unusable."""
        if not self._monitor_read:
            self._monitor = read_monitor(self._session.get_modelmeta().custom_metadata_map, self.path.name)
            self._monitor_read = True
        return self._monitor

    def _contract(self) -> tuple[PreprocessContract, str]:
        meta = self._session.get_modelmeta().custom_metadata_map
        try:
            if METADATA_KEY not in meta:
                return infer_contract(self.input_shape), "inferred"
            contract = PreprocessContract.from_json(meta[METADATA_KEY])
        except ContractError as exc:
            raise ModelError(f"{self.path.name}: {_first_line(exc)}") from None
        if len(self.input_shape) != 4:
            raise ModelError(f"{self.path.name}: model input must have rank 4, got shape {list(self.input_shape)}")
        for want, have in zip(contract.input_shape[1:], self.input_shape[1:], strict=True):
            if isinstance(have, int) and have != want:
                raise ModelError(f"{self.path.name}: {METADATA_KEY} expects input {list(contract.input_shape)}, "
                                 f"the model's input is {list(self.input_shape)}")
        return contract, "metadata"

    def predict(self, x: np.ndarray) -> float:
        """The network's normalised steering (-1..1 for a trained model) for one preprocessed input batch of 1,
        before the serving gain (``DrivePipeline`` applies it)."""
        out = self._session.run(self._outputs, {self.input_name: x})[0]
        return float(out.reshape(-1)[0])

    def warm_up(self) -> None:
        """One full preprocessing + inference pass on a synthetic camera frame, before the server listens.

        Allocates ORT's buffers before the first real frame and checks, through THE preprocessing
        function and at the decode scale serving uses, that the contract works on this input and that
        the output is one finite value: a model that answers NaN is refused here, not on every frame.
        """
        from drive_server.serving.preprocess import jpeg_reduction, preprocess
        from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH

        reduce = jpeg_reduction(self.contract)
        h, w = FRAME_HEIGHT // reduce, FRAME_WIDTH // reduce
        ramp = np.linspace(0, 255, w, dtype=np.float32)[None, :, None] * np.linspace(0.3, 1.0, h)[:, None, None]
        frame = np.broadcast_to(ramp, (h, w, 3)).astype(np.uint8)
        try:
            x = preprocess(frame, self.contract)
            out = self._session.run(self._outputs, {self.input_name: x})[0]
        except Exception as exc:
            raise ModelError(f"{self.path.name}: preprocessing + inference on a test frame "
                             f"({list(self.contract.input_shape)} input) failed: {_first_line(exc)}") from None
        out = np.asarray(out)
        if out.size != 1:
            raise ModelError(f"{self.path.name}: output must hold one steering value, got shape {list(out.shape)}")
        if not np.isfinite(out).all():
            raise ModelError(f"{self.path.name}: output on a test frame is not finite ({float(out.reshape(-1)[0])!r}); "
                             "check the model's weights and its preprocessing contract")

    def describe(self) -> str:
        return (f"{self.path.name} input {self.input_name}{list(self.input_shape)} "
                f"provider {self.config.provider} threads {self.config.threads}, contract ({self.contract_source}) "
                f"{self.contract.width}x{self.contract.height} {self.contract.color} {self.contract.layout} "
                f"crop {self.contract.crop_top}..{self.contract.crop_bottom}"
                + (f" decode 1/{self.contract.decode_reduce}" if self.contract.decode_reduce else "")
                + (f" edges {self.contract.blank_columns} blanked" if self.contract.blank_columns else "")
                + (f", serving: {self.serving.describe()}" if self.serving.asks_anything else ""))
