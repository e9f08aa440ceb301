"""Move a gain multiplied into an older model file's graph into its serving metadata
(``drive_server.serving.settings``).

Files exported before the gain became a serving setting end in ``Mul(steering, S)`` and record ``output_scale:
S``. They keep serving as they are; this rewrites one so its graph answers the network's own prediction (what
``rbc score`` and the cross-validation should score) and the file asks drive_server for gain S instead: the
served steering is the same, the open-loop figures become the network's. Verified with ONNX Runtime.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnx import numpy_helper

from drive_server.serving.settings import SERVING_KEY, Serving
from models.onnxfiles.onnx_metadata import read_steering_graph, set_model_metadata
from protocol import runrecords
from protocol.errors import BadValue

TOLERANCE = 1e-5


class GainError(BadValue):
    """The file's gain cannot be moved; the message is one line."""


def _constant(proto: onnx.ModelProto, name: str) -> np.ndarray | None:
    for init in proto.graph.initializer:
        if init.name == name:
            return numpy_helper.to_array(init)
    for node in proto.graph.node:
        if node.op_type == "Constant" and node.output[0] == name:
            return numpy_helper.to_array(node.attribute[0].t)
    return None


def move_gain_to_serving(src: Path, dst: Path, seed: int = 0) -> float:
    """Write ``dst`` (atomically): ``src`` without its final ``Mul`` by its recorded ``output_scale``, asking
    drive_server for that gain (times any gain it already asks). Return the max |gain * dst - src| on random
    inputs (``seed``); ``GainError`` if the file has no such multiplication."""
    model = read_steering_graph(src, GainError)
    proto, info = model.proto, dict(model.info)
    scale = float(model.info.get("output_scale", 1.0))
    last = proto.graph.node[-1]
    if scale == 1.0 or last.op_type != "Mul" or last.output[0] != model.output_name:
        raise GainError(f"{src}: its graph carries no recorded output scale to move")
    factor = next(((i, c) for i, n in enumerate(last.input) if (c := _constant(proto, n)) is not None
                   and c.size == 1 and abs(float(c.reshape(-1)[0]) - scale) < 1e-6), None)
    if factor is None:
        raise GainError(f"{src}: its last node does not multiply by the recorded output scale {scale:g}")
    kept = last.input[1 - factor[0]]
    del proto.graph.node[-1]
    for node in proto.graph.node:  # the node that made the multiplied value now writes the output
        node.output[:] = [model.output_name if n == kept else n for n in node.output]
    used = {n for node in proto.graph.node for n in node.input}
    dead = [n for n in proto.graph.node if n.op_type == "Constant" and n.output[0] not in used]
    for node in dead:
        proto.graph.node.remove(node)
    asked = Serving.from_json(model.meta.get(SERVING_KEY))
    info.pop("output_scale")
    set_model_metadata(proto, info, asked.smoothing, gain=asked.gain * scale)
    onnx.checker.check_model(proto)
    with runrecords.atomic_path(Path(dst)) as tmp:
        onnx.save(proto, str(tmp))
        worst = _verify(Path(src), tmp, model.contract.input_shape[1:], scale, seed)
    return worst


def _verify(src: Path, dst: Path, shape: tuple[int, ...], scale: float, seed: int) -> float:
    x = np.random.default_rng(seed).random((4, *shape), dtype=np.float32)
    before, after = (ort.InferenceSession(str(p), providers=["CPUExecutionProvider"]) for p in (src, dst))
    want = before.run(None, {before.get_inputs()[0].name: x})[0]
    got = after.run(None, {after.get_inputs()[0].name: x})[0] * scale
    worst = float(np.abs(got - want).max())
    if not np.isfinite(worst) or worst >= TOLERANCE:
        raise GainError(f"{dst}: gain x the rewritten file differs from {src.name} by {worst:.3g}")
    return worst
