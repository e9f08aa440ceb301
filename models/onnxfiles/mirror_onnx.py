"""Mirror-average an existing ONNX steering model: the file answers (f(x) - f(mirror x)) / 2.

``rbc train --mirror-average`` does this at export (``models.networks.nets.MirrorAveraged``); this module does it to
a model file whose training run is gone (the bundled generalists, a model trained elsewhere), at the ONNX
graph level: the input and its mirror image go through the unchanged network as one batch of 2N, and the
two halves' difference, halved, is the output. The original network's left-right lean cancels, and so
does any constant bias; so would a lean the task asks for: a model that keeps to the right lane of a
two-lane road (the rigorous behavior) is refused. Verified against the original with ONNX Runtime before
the file is kept.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnx import helper, numpy_helper

from drive_server.serving.contract import METADATA_MODEL_INFO_KEY, PreprocessContract
from drive_server.serving.settings import SERVING_KEY, Serving, check_gain
from models.data.behavior import keeps_lane
from models.onnxfiles.onnx_metadata import read_steering_graph, set_model_metadata
from protocol import runrecords
from protocol.errors import BadValue

TOLERANCE = 1e-4
_PREFIX = "rbc_mirror_"


class MirrorError(BadValue):
    """The model cannot be mirror-averaged; the message is one line."""


def mirror_average_onnx(src: Path, dst: Path, smoothing: float | None = None, seed: int = 0,
                        gain: float | None = None) -> float:
    """Write ``dst`` (atomically) from ``src``; return the max |mirrored - (f(x) - f(mirror x)) / 2| on random
    inputs (``seed``). The file asks drive_server for ``smoothing`` and ``gain`` (drive_server.serving.settings; None:
    what ``src`` asks for), as a recipe's ``[export]`` does."""
    model = read_steering_graph(src, MirrorError)
    try:
        asked = Serving.from_json(model.meta.get(SERVING_KEY))
        serving = Serving(asked.smoothing if smoothing is None else smoothing,
                          asked.gain if gain is None else check_gain(gain))
    except ValueError as exc:
        raise MirrorError(f"{src}: {exc}" if smoothing is None and gain is None else str(exc)) from None
    proto, graph, info, shape, contract = model.proto, model.proto.graph, model.info, model.shape, model.contract
    if info.get("mirror_average"):
        raise MirrorError(f"{src}: already mirror-averaged (its {METADATA_MODEL_INFO_KEY} says so)")
    if keeps_lane(info.get("behavior")):
        raise MirrorError(f"{src}: a {info['behavior']} model keeps to one lane of a two-lane road, a left-right "
                          f"asymmetric task; the average would steer it to the road's middle")
    if isinstance(shape[0], int):
        raise MirrorError(f"{src}: the input has a fixed batch of {shape[0]}: the mirrored frame cannot run beside it")
    width_axis = 2 if contract.layout == "nhwc" else 3

    image, steering = model.input_name, model.output_name
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

    set_model_metadata(proto, {**info, "mirror_average": True}, serving.smoothing, gain=serving.gain)
    onnx.checker.check_model(proto)
    with runrecords.atomic_path(Path(dst)) as tmp:
        onnx.save(proto, str(tmp))
        worst = _verify(Path(src), tmp, contract, width_axis, seed)
    return worst


def _verify(src: Path, dst: Path, contract: PreprocessContract, width_axis: int, seed: int) -> float:
    """The mirrored file against the original's average on random inputs, singly and as a batch; MirrorError
    beyond ``TOLERANCE``."""
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
