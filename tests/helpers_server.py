"""Helpers for the drive-server tests: tiny ONNX models built in the session, frames, bad model files."""

from __future__ import annotations

import base64
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
SAMPLE_LOG = REPO / "tests" / "data" / "udacity-sample"


def build_shallow(path: Path, **kwargs) -> Path:
    """The paper's shallow CNN with random weights (14,065 parameters, ~57 KB)."""
    from tools.bench.onnx_builders import save_model

    return save_model("shallow", path, **kwargs)


def build_graph(path: Path, inputs: list[tuple[str, list]], outputs: list[tuple[str, list]], nodes: list) -> Path:
    """A hand-made ONNX graph (for malformed-model tests)."""
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        nodes, "bad",
        [helper.make_tensor_value_info(n, TensorProto.FLOAT, s) for n, s in inputs],
        [helper.make_tensor_value_info(n, TensorProto.FLOAT, s) for n, s in outputs],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    path.write_bytes(model.SerializeToString())
    return path


def jpeg_b64(width: int, height: int, seed: int = 0) -> str:
    """A base64 JPEG of the given size (for wrong-size frames)."""
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 255, (height, width, 3), dtype=np.uint8)
    ok, buf = cv2.imencode(".jpg", img)
    assert ok
    return base64.b64encode(buf.tobytes()).decode("ascii")


def run_server_cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    """Run ``python -m drive_server ARGS`` to completion (for the exit-code tests)."""
    return subprocess.run([sys.executable, "-m", "drive_server", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO)
