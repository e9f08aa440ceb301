"""The frame-statistics monitor: how far a frame's brightness and contrast are from those of the nominal frames.

Why (docs/experiments.md, "A camera check beside the ensemble"): two thirds of the benchmark's misbehaviours come
in light 4-12 times the default, where the frames wash out. There every network steers alike (the ensemble sees
nothing) and a washed-out frame is easy to reconstruct (the autoencoder sees nothing either), but its per-channel
brightness and contrast lie far outside those of the frames the model was trained on. This is the camera-health
check of a vehicle's perception stack (over- and under-exposure, a blocked lens), fitted to the model's own input.

The score of a frame: with ``f`` its six statistics (the mean and the standard deviation of each colour channel of
the model's preprocessed input), ``mu`` their mean over nominal frames and ``C`` their covariance, shrunk a little
toward its diagonal so that a near-singular one stays usable, the Mahalanobis distance ``sqrt((f - mu)' C^-1 (f -
mu))``. Six numbers per frame: it costs far less than a network.

:func:`combine_scores` puts it beside another monitor's graph: the larger of the two scores, each divided by its
own alarm threshold on the calibration data, so that either alone can raise a warning.
"""

from __future__ import annotations

import numpy as np

from drive_server.serving.contract import PreprocessContract
from protocol.errors import BadValue

SCORE_NAME = "framestats"
#: The covariance's shrinkage toward its diagonal (a share of its mean variance added to the diagonal).
SHRINK = 1e-3
#: Largest |graph - numpy| on the frames the graph is checked on before it is kept.
TOLERANCE = 1e-3
#: The fewest nominal frames to fit the statistics on: more than the 27 numbers fitted (six means, 21 covariances).
MIN_FRAMES = 30


def _axes(contract: PreprocessContract) -> tuple[int, int]:
    return (1, 2) if contract.layout == "nhwc" else (2, 3)


def frame_features(frames: np.ndarray, contract: PreprocessContract) -> np.ndarray:
    """(N, 6): each channel's mean, then each channel's standard deviation, of preprocessed frames."""
    x = np.asarray(frames, np.float64)
    axes = _axes(contract)
    mean = x.mean(axis=axes)
    std = np.sqrt(np.maximum((x * x).mean(axis=axes) - mean * mean, 0.0))
    return np.concatenate([mean, std], axis=1)


def fit_framestats(frames: np.ndarray, contract: PreprocessContract) -> tuple[np.ndarray, np.ndarray]:
    """``(mu, whiten)`` from nominal frames: ``||(f - mu) @ whiten||`` is the Mahalanobis distance."""
    return fit_features(frame_features(frames, contract))


def fit_features(f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_framestats` from the frames' features (:func:`frame_features`), gathered run by run."""
    if len(f) < MIN_FRAMES:
        raise BadValue(f"the frame statistics need at least {MIN_FRAMES} nominal frames (--data), got {len(f)}")
    mu = f.mean(axis=0)
    cov = np.cov(f, rowvar=False)
    cov = cov + np.eye(len(cov)) * (SHRINK * float(np.trace(cov)) / len(cov) + 1e-12)
    whiten = np.linalg.cholesky(np.linalg.inv(cov))  # inv(C) = L L': |(f - mu) L| = the distance
    return mu, whiten


def framestats_scores(frames: np.ndarray, contract: PreprocessContract, mu: np.ndarray,
                      whiten: np.ndarray) -> np.ndarray:
    """The score in numpy (what the graph computes), (N,)."""
    d = (frame_features(frames, contract) - mu) @ whiten
    return np.sqrt((d * d).sum(axis=1))


def _reduce(op: str, x: str, axes: list[int], out: str, opset: int) -> tuple[list, list]:
    """A Reduce node without keeping the reduced axes; axes are an attribute up to opset 17, an input from 18."""
    from onnx import TensorProto, helper

    if opset < 18:
        return [helper.make_node(op, [x], [out], axes=axes, keepdims=0)], []
    name = f"{out}_axes"
    return ([helper.make_node(op, [x, name], [out], keepdims=0)],
            [helper.make_tensor(name, TensorProto.INT64, [len(axes)], axes)])


def framestats_graph(contract: PreprocessContract, mu: np.ndarray, whiten: np.ndarray, opset: int = 17,
                     ir_version: int = 8) -> bytes:
    """ONNX bytes: the preprocessed frame ``image`` -> ``score`` per frame, checked against numpy on random frames."""
    import onnx
    from onnx import TensorProto, helper

    axes = list(_axes(contract))
    mean, mean_inits = _reduce("ReduceMean", "image", axes, "fs_mean", opset)
    msq, msq_inits = _reduce("ReduceMean", "fs_sq", axes, "fs_msq", opset)
    d2, d2_inits = _reduce("ReduceSumSquare", "fs_white", [1], "fs_d2", opset)
    nodes = [*mean, helper.make_node("Mul", ["image", "image"], ["fs_sq"]), *msq,
             helper.make_node("Mul", ["fs_mean", "fs_mean"], ["fs_mean2"]),
             helper.make_node("Sub", ["fs_msq", "fs_mean2"], ["fs_var0"]),
             helper.make_node("Relu", ["fs_var0"], ["fs_var"]),  # E[x^2] - E[x]^2 can round below 0
             helper.make_node("Sqrt", ["fs_var"], ["fs_std"]),
             helper.make_node("Concat", ["fs_mean", "fs_std"], ["fs_f"], axis=1),
             helper.make_node("Sub", ["fs_f", "fs_mu"], ["fs_centred"]),
             helper.make_node("MatMul", ["fs_centred", "fs_whiten"], ["fs_white"]), *d2]
    inits = [helper.make_tensor("fs_mu", TensorProto.FLOAT, [len(mu)], mu.astype(np.float32)),
             helper.make_tensor("fs_whiten", TensorProto.FLOAT, list(whiten.shape),
                                whiten.astype(np.float32).reshape(-1)),
             *mean_inits, *msq_inits, *d2_inits]
    nodes.append(helper.make_node("Sqrt", ["fs_d2"], ["score"]))
    shape: list[str | int | None] = ["batch", *contract.input_shape[1:]]
    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, shape)
    score = helper.make_tensor_value_info("score", TensorProto.FLOAT, ["batch"])
    graph = helper.make_graph(nodes, "rbc_frame_statistics", [image], [score], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)], ir_version=ir_version)
    onnx.checker.check_model(model)
    out = model.SerializeToString()
    rng = np.random.default_rng(0)
    frames = (rng.random((3, *contract.input_shape[1:]), dtype=np.float32) - 0.5).astype(np.float32)
    _check(out, [frames], framestats_scores(frames, contract, mu, whiten), "the frame statistics' graph")
    return out


def combine_scores(first: bytes, second: bytes, scales: tuple[float, float]) -> bytes:
    """ONNX bytes: ``max(first / scales[0], second / scales[1])`` per frame. ``first`` keeps its inputs (the frame,
    and the served steering if it takes it); ``second`` takes the frame only (the frame statistics)."""
    import onnx
    from onnx import TensorProto, helper

    if min(scales) <= 0 or not np.isfinite(scales).all():
        raise BadValue(f"each part's scale (its alarm threshold) must be > 0, got {scales[0]:g} and {scales[1]:g}")
    a, b = onnx.load_from_string(first), onnx.load_from_string(second)
    if len(b.graph.input) != 1:
        raise BadValue("the second part of a combined monitor takes the frame only")
    image = a.graph.input[0].name

    def renamed(model: onnx.ModelProto, prefix: str, keep: dict[str, str]) -> tuple[list, list]:
        def name(n: str) -> str:
            return keep.get(n, f"{prefix}{n}") if n else n

        nodes = []
        for node in model.graph.node:
            copy = onnx.NodeProto()
            copy.CopyFrom(node)
            copy.input[:] = [name(n) for n in node.input]
            copy.output[:] = [name(n) for n in node.output]
            copy.name = f"{prefix}{node.name}" if node.name else ""
            nodes.append(copy)
        inits = []
        for init in model.graph.initializer:
            copy = onnx.TensorProto()
            copy.CopyFrom(init)
            copy.name = name(init.name)
            inits.append(copy)
        return nodes, inits

    keep_a = {i.name: i.name for i in a.graph.input}
    nodes_a, inits_a = renamed(a, "p0_", keep_a)
    nodes_b, inits_b = renamed(b, "p1_", {b.graph.input[0].name: image})
    out_a, out_b = f"p0_{a.graph.output[0].name}", f"p1_{b.graph.output[0].name}"
    inits = [*inits_a, *inits_b, helper.make_tensor("combo_scale0", TensorProto.FLOAT, [], [float(scales[0])]),
             helper.make_tensor("combo_scale1", TensorProto.FLOAT, [], [float(scales[1])]),
             helper.make_tensor("combo_flat", TensorProto.INT64, [1], [-1])]
    nodes = [*nodes_a, *nodes_b,
             helper.make_node("Reshape", [out_a, "combo_flat"], ["combo_a"]),
             helper.make_node("Reshape", [out_b, "combo_flat"], ["combo_b"]),
             helper.make_node("Div", ["combo_a", "combo_scale0"], ["combo_na"]),
             helper.make_node("Div", ["combo_b", "combo_scale1"], ["combo_nb"]),
             helper.make_node("Max", ["combo_na", "combo_nb"], ["score"])]
    score = helper.make_tensor_value_info("score", TensorProto.FLOAT, ["batch"])
    graph = helper.make_graph(nodes, "rbc_combined_monitor", list(a.graph.input), [score], inits)
    opset = max(o.version for o in a.opset_import if o.domain in ("", "ai.onnx"))
    if max(o.version for o in b.opset_import if o.domain in ("", "ai.onnx")) != opset:
        raise BadValue("the two parts of a combined monitor must use the same ONNX opset")
    model = helper.make_model(graph, opset_imports=list(a.opset_import), ir_version=a.ir_version)
    onnx.checker.check_model(model)
    return model.SerializeToString()


def _check(graph: bytes, feeds: list[np.ndarray], want: np.ndarray, what: str) -> None:
    import onnxruntime as ort

    session = ort.InferenceSession(graph, providers=["CPUExecutionProvider"])
    names = [i.name for i in session.get_inputs()]
    got = np.asarray(session.run(None, dict(zip(names, feeds, strict=True)))[0]).reshape(-1)
    worst = float(np.abs(got - want).max())
    if not np.isfinite(worst) or worst >= TOLERANCE * max(1.0, float(np.abs(want).max())):
        raise BadValue(f"{what} differs from numpy by {worst:.3g} on random frames")
