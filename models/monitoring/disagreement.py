"""A monitor that needs no training: the steering model's disagreement with itself on the same frame moved a few
pixels sideways (test-time augmentation). Where the model is sure, a small shift changes its answer little;
on frames unlike its training, or near its decision boundaries, the two answers part. The graph holds the
steering graph twice, so it costs two steering inferences per frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from models.onnxfiles.onnx_metadata import read_steering_graph
from protocol.errors import BadValue

SCORE_NAME = "shift"
#: Pixels of the 64-pixel-wide input the second view is moved by (about 1.5 degrees of heading at 64x64).
SHIFT_PIXELS = 3


def shift_disagreement_graph(src: Path, pixels: int = SHIFT_PIXELS) -> bytes:
    """ONNX bytes: the steering model's input -> |s(x) - s(x moved ``pixels`` left, edge repeated)| per frame."""
    import onnx
    from onnx import TensorProto, compose, helper

    g = read_steering_graph(src, BadValue)
    axis = 2 if g.contract.layout.lower() == "nhwc" else 3
    width = g.contract.width
    if not 0 < pixels < width:
        raise BadValue(f"shift must be 1..{width - 1} pixels, got {pixels}")
    x = g.input_name
    consts = [helper.make_tensor("shift_starts", TensorProto.INT64, [1], [pixels]),
              helper.make_tensor("shift_ends", TensorProto.INT64, [1], [width]),
              helper.make_tensor("shift_axes", TensorProto.INT64, [1], [axis]),
              helper.make_tensor("shift_pads", TensorProto.INT64, [8],
                                 [0, 0, 0, 0] + [pixels if i == axis else 0 for i in range(4)]),
              helper.make_tensor("score_axes", TensorProto.INT64, [1], [1])]
    nodes = [helper.make_node("Slice", [x, "shift_starts", "shift_ends", "shift_axes"], ["shift_cut"]),
             helper.make_node("Pad", ["shift_cut", "shift_pads"], ["shift_x"], mode="edge")]
    outs = []
    for prefix, source in (("a_", x), ("b_", "shift_x")):
        part = compose.add_prefix(g.proto, prefix)
        for node in part.graph.node:
            node.input[:] = [source if n == prefix + x else n for n in node.input]
        nodes.extend(part.graph.node)
        consts.extend(part.graph.initializer)
        outs.append(prefix + g.output_name)
    nodes += [helper.make_node("Sub", outs, ["shift_diff"]), helper.make_node("Abs", ["shift_diff"], ["shift_abs"]),
              helper.make_node("Flatten", ["shift_abs"], ["shift_flat"], axis=1),
              helper.make_node("ReduceMean", ["shift_flat", "score_axes"], ["score"], keepdims=0)]
    image = next(i for i in g.proto.graph.input if i.name == x)
    score = helper.make_tensor_value_info("score", TensorProto.FLOAT, ["batch"])
    graph = helper.make_graph(nodes, "rbc_shift_disagreement", [image], [score], consts)
    opset = max((o.version for o in g.proto.opset_import if o.domain in ("", "ai.onnx")), default=17)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", max(opset, 18))],
                              ir_version=g.proto.ir_version)
    onnx.checker.check_model(model)
    return model.SerializeToString()


def graph_scores(graph: bytes, frames: np.ndarray, batch_size: int = 256,
                 steering: np.ndarray | None = None) -> np.ndarray:
    """A monitor graph's per-frame scores on preprocessed frames (ONNX Runtime; any monitor graph); ``steering``:
    the served network's output on each frame, for a graph that takes it as its second input."""
    import onnxruntime as ort

    session = ort.InferenceSession(graph, providers=["CPUExecutionProvider"])
    names = [i.name for i in session.get_inputs()]
    if (len(names) > 1) != (steering is not None):
        raise BadValue(f"the monitor's graph takes {len(names)} input(s); give the served steering exactly when it "
                       "takes two")
    out = []
    for start in range(0, len(frames), batch_size):
        feed = {names[0]: np.ascontiguousarray(frames[start:start + batch_size], dtype=np.float32)}
        if steering is not None:
            feed[names[1]] = np.asarray(steering[start:start + batch_size], np.float32).reshape(-1, 1)
        out.append(np.asarray(session.run(None, feed)[0]).reshape(-1))
    return np.concatenate(out) if out else np.zeros(0, np.float32)
