"""Export a trained network to ONNX with its preprocessing contract, and prove the export is faithful.

The contract goes into the model's metadata (``rbc.preprocess``) so the drive server preprocesses
exactly as training did. ONNX Runtime's outputs are compared with PyTorch's on real frames; a
mismatch fails the run loudly instead of shipping a model that drives differently than it validated.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch
from torch import nn

from drive_server.serving.contract import METADATA_KEY, PreprocessContract
from drive_server.serving.preprocess import to_input_tensor
from drive_server.serving.settings import NO_GAIN
from drive_server.serving.smoothing import OFF
from models.networks.nets import ContractInput
from models.onnxfiles.onnx_metadata import set_model_metadata
from protocol import runrecords
from protocol.errors import UserError

log = logging.getLogger(__name__)

INPUT_NAME = "image"
OUTPUT_NAME = "steering"
OPSET = 17
TOLERANCE = 1e-4


class ExportError(UserError, RuntimeError):
    """The ONNX model does not reproduce the PyTorch model."""

    hint = "pass an .onnx model exported by rbc train, or a bundled one from models/pretrained/"


def export_onnx(net: nn.Module, contract: PreprocessContract, info: Mapping[str, object], path: Path,
                frames: np.ndarray, smoothing: float = OFF, gain: float = NO_GAIN) -> float:
    """Write ``path`` (atomically) and return the max |ORT - torch| on ``frames`` (uint8 network images).

    ``smoothing`` < 1 and ``gain`` != 1: the model asks drive_server to serve it so (``rbc.serving``); the graph
    is the network's alone.
    """
    model = ContractInput(net, contract.layout).eval()
    dummy = torch.zeros(contract.input_shape, dtype=torch.float32)
    path = Path(path)
    with runrecords.atomic_path(path) as tmp:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the TorchScript exporter is deprecated but needs no onnxscript
            torch.onnx.export(model, (dummy,), str(tmp), dynamo=False, opset_version=OPSET,
                              input_names=[INPUT_NAME], output_names=[OUTPUT_NAME],
                              dynamic_axes={INPUT_NAME: {0: "batch"}, OUTPUT_NAME: {0: "batch"}})
        proto = onnx.load(str(tmp))
        set_model_metadata(proto, info, smoothing, contract, gain)
        proto.producer_name = "robust-behavioral-cloning"
        onnx.checker.check_model(proto)
        onnx.save(proto, str(tmp))
        diff = verify_onnx(tmp, model, contract, frames)
    log.debug("exported %s (max |onnxruntime - torch| = %.2e on %d frames)", path, diff, len(frames))
    return diff


def verify_onnx(path: Path, model: nn.Module, contract: PreprocessContract, frames: np.ndarray) -> float:
    """Compare ONNX Runtime with PyTorch on real frames; raise ``ExportError`` beyond ``TOLERANCE``."""
    x = to_input_tensor(frames, contract)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    got_contract = PreprocessContract.from_json(session.get_modelmeta().custom_metadata_map[METADATA_KEY])
    if got_contract != contract:
        raise ExportError(f"{path}: contract in metadata {got_contract} != {contract}")
    ort_out = np.concatenate([session.run(None, {INPUT_NAME: x[i:i + 1]})[0] for i in range(len(x))])
    ort_batch = session.run(None, {INPUT_NAME: x})[0]
    with torch.no_grad():
        ref = model.eval()(torch.from_numpy(x)).numpy()
    diff = float(max(np.abs(ort_out - ref).max(), np.abs(ort_batch - ref).max()))
    if not np.isfinite(diff) or diff >= TOLERANCE:
        raise ExportError(f"{path}: ONNX Runtime differs from PyTorch by {diff:.3g} (tolerance {TOLERANCE})")
    return diff
