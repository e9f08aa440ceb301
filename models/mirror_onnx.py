"""Mirror-average an existing ONNX steering model: the file answers (f(x) - f(mirror x)) / 2.

``rbc train --mirror-average`` does this at export (``models.nets.MirrorAveraged``); this module does it to
a model file whose training run is gone (the bundled generalists, a model trained elsewhere), at the ONNX
graph level: the input and its mirror image go through the unchanged network as one batch of 2N, and the
two halves' difference, halved, is the output. The original network's left-right lean cancels, and so
does any constant bias; so would a lean the task asks for: a model that keeps to the right lane of a
two-lane road (the rigorous behavior) is refused. Verified against the original with ONNX Runtime before
the file is kept.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnx import helper, numpy_helper

from drive_server import runrecords
from drive_server.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY, PreprocessContract, infer_contract
from drive_server.smoothing import OFF
from models.onnx_metadata import set_model_metadata

TOLERANCE = 1e-4
_PREFIX = "rbc_mirror_"
#: behaviors that keep to a lane (trained without flips, models.behavior): mirroring would undo what they learnt
LANE_KEEPING = frozenset({"rigorous"})


class MirrorError(ValueError):
    """The model cannot be mirror-averaged; the message is one line."""


def mirror_average_onnx(src: Path, dst: Path, serve_smooth: float = OFF, seed: int = 0) -> float:
    """Write ``dst`` (atomically) from ``src``; return the max |mirrored - (f(x) - f(mirror x)) / 2| on random
    inputs (``seed``). ``serve_smooth`` < 1 also asks drive_server to smooth each client's steering so."""
    try:
        proto = onnx.load(str(src))
    except Exception as exc:  # not a file, not protobuf, truncated: whatever onnx raises
        first = str(exc).strip().splitlines()[0][:120] if str(exc).strip() else type(exc).__name__
        raise MirrorError(f"{src}: not an ONNX model ({first})") from None
    graph = proto.graph
    inputs = [i for i in graph.input if i.name not in {t.name for t in graph.initializer}]
    if len(inputs) != 1 or len(graph.output) != 1:
        raise MirrorError(f"{src}: expected one image input and one steering output")
    meta = {p.key: p.value for p in proto.metadata_props}
    info = json.loads(meta.get(METADATA_MODEL_INFO_KEY, "{}") or "{}")
    if isinstance(info, dict) and info.get("mirror_average"):
        raise MirrorError(f"{src}: already mirror-averaged (its {METADATA_MODEL_INFO_KEY} says so)")
    if isinstance(info, dict) and info.get("behavior") in LANE_KEEPING:
        raise MirrorError(f"{src}: a {info['behavior']} model keeps to one lane of a two-lane road, a left-right "
                          f"asymmetric task; the average would steer it to the road's middle")
    dims = inputs[0].type.tensor_type.shape.dim
    shape = [d.dim_value if d.HasField("dim_value") else d.dim_param or None for d in dims]
    if len(shape) != 4:
        raise MirrorError(f"{src}: the input must have rank 4, not {len(shape)}")
    if isinstance(shape[0], int):
        raise MirrorError(f"{src}: the input has a fixed batch of {shape[0]}: the mirrored frame cannot run beside it")
    contract = (PreprocessContract.from_json(meta[METADATA_KEY]) if METADATA_KEY in meta
                else infer_contract(tuple(shape)))
    width_axis = 2 if contract.layout == "nhwc" else 3

    image, steering = inputs[0].name, graph.output[0].name
    both, pair, first, second, diff = (f"{_PREFIX}{n}" for n in ("both", "pair", "first", "second", "diff"))
    for node in graph.node:  # the network now reads the batch of 2N and writes the pair
        node.input[:] = [both if n == image else n for n in node.input]
        node.output[:] = [pair if n == steering else n for n in node.output]
    consts = {"starts": [-1], "ends": [np.iinfo(np.int64).min], "axes": [width_axis], "steps": [-1]}
    graph.initializer.extend(numpy_helper.from_array(np.array(v, np.int64), f"{_PREFIX}{k}") for k, v in consts.items())
    graph.initializer.append(numpy_helper.from_array(np.array(0.5, np.float32), f"{_PREFIX}half"))
    head = [helper.make_node("Slice", [image, *(f"{_PREFIX}{k}" for k in consts)], [f"{_PREFIX}mirrored"]),
            helper.make_node("Concat", [image, f"{_PREFIX}mirrored"], [both], axis=0)]
    tail = [helper.make_node("Split", [pair], [first, second], axis=0),
            helper.make_node("Sub", [first, second], [diff]),
            helper.make_node("Mul", [diff, f"{_PREFIX}half"], [steering])]
    nodes = [*head, *graph.node, *tail]
    del graph.node[:]
    graph.node.extend(nodes)
    del graph.value_info[:]  # shapes inside changed (batch 2N); ONNX Runtime infers them again

    set_model_metadata(proto, {**(info if isinstance(info, dict) else {}), "mirror_average": True}, serve_smooth)
    onnx.checker.check_model(proto)
    with runrecords.atomic_path(Path(dst)) as tmp:
        onnx.save(proto, str(tmp))
        worst = _verify(Path(src), tmp, contract, width_axis, seed)
    return worst


def _verify(src: Path, dst: Path, contract: PreprocessContract, width_axis: int, seed: int) -> float:
    """The mirrored file against the original on random inputs, singly and as a batch; MirrorError beyond
    ``TOLERANCE``."""
    rng = np.random.default_rng(seed)
    x = (rng.random((4, *contract.input_shape[1:]), dtype=np.float32) - 0.5).astype(np.float32)
    original, mirrored = (ort.InferenceSession(str(p), providers=["CPUExecutionProvider"]) for p in (src, dst))

    def run(session: ort.InferenceSession, batch: np.ndarray) -> np.ndarray:
        return session.run(None, {session.get_inputs()[0].name: batch})[0].reshape(len(batch), -1)

    want = 0.5 * (run(original, x) - run(original, np.ascontiguousarray(np.flip(x, axis=width_axis))))
    got = np.concatenate([run(mirrored, x[i:i + 1]) for i in range(len(x))])
    worst = float(max(np.abs(got - want).max(), np.abs(run(mirrored, x) - want).max()))
    if not np.isfinite(worst) or worst >= TOLERANCE:
        raise MirrorError(f"{dst}: the mirrored model differs from (f(x) - f(mirror x)) / 2 by {worst:.3g}")
    return worst
