"""MC-dropout for a network trained with dropout: the served network with dropout left on, sampled a few times per
frame, its spread the score (Grewal, Tonella and Stocco, ICST 2024: 97/96/93 % recall at 1/2/3 s on their
simulator). It needs no other training run, so it suits a model whose recipe is costly to train again
(``unity.onnx``: 39 recordings).

How: dropout after a hidden ReLU layer zeroes some of its units and scales the rest by 1/(1-p); that is the same as
scaling the matching input columns of the NEXT dense layer's weights. Each sample is therefore a copy of the served
network with one fixed mask baked into those weights, drawn once from ``seed``, and the samples are the members of
the ensemble score (:mod:`models.monitoring.ensemble`): ``|served - mean| + std`` over them. Fixed masks keep the
score a deterministic function of the frame (the same frame, the same score, in the server, the benchmark and the
calibration) where sampling anew per frame would make the threshold a matter of luck; the rest of the graph (the
convolutions, the mirror average) is the served network's, untouched.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drive_server.serving.monitor import MONITOR_GRAPH_KEY, MONITOR_KEY
from protocol.errors import BadValue

if TYPE_CHECKING:
    import onnx

SCORE_NAME = "mcdropout"
#: Samples (masked copies) per frame: each runs the network once more.
DEFAULT_SAMPLES = 4


def dropout_rate(model: Path) -> float:
    """The dropout rate the served network was trained with (its architecture's, from the file's ``rbc.model``)."""
    import onnx

    from models.networks.architectures import ARCHITECTURES

    meta = {p.key: p.value for p in onnx.load(str(model), load_external_data=False).metadata_props}
    try:
        arch = json.loads(meta.get("rbc.model", "{}")).get("arch")
    except ValueError:
        arch = None
    spec = ARCHITECTURES.get(str(arch))
    if spec is None or not spec.dropout:
        raise BadValue(f"{Path(model).name}: {'a ' + str(arch) if spec else 'an unknown'} network, trained without "
                       "dropout; MC-dropout needs one trained with it (shallow, shallow-wide)",
                       "use --score ensemble with networks of its recipe trained with other seeds")
    return float(spec.dropout)


def dropout_members(model: Path, folder: Path, samples: int = DEFAULT_SAMPLES, seed: int = 0) -> list[Path]:
    """``samples`` copies of ``model`` in ``folder``, each with one dropout mask per hidden dense layer baked into
    the next layer's weights (module docstring); BadValue if the network has no dense ReLU head to drop out."""
    import onnx
    from onnx import numpy_helper

    if samples < 2:
        raise BadValue(f"MC-dropout needs at least 2 samples, got {samples}")
    rate = dropout_rate(model)
    proto = onnx.load(str(model))
    layers = _dense_after_relu(proto)
    kept = [(p.key, p.value) for p in proto.metadata_props if p.key not in (MONITOR_KEY, MONITOR_GRAPH_KEY)]
    del proto.metadata_props[:]  # a monitor the served file carries is never a member's: keep the copies small
    for key, value in kept:
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    weights = {i.name: i for i in proto.graph.initializer}
    original = {name: numpy_helper.to_array(weights[name]) for name, _ in layers}
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for k in range(samples):
        for name, columns in layers:
            w = original[name]
            units = w.shape[1] if columns else w.shape[0]
            mask = np.asarray(rng.random(units) >= rate, w.dtype) / np.asarray(1.0 - rate, w.dtype)
            weights[name].CopyFrom(numpy_helper.from_array(w * (mask[None, :] if columns else mask[:, None]), name))
        path = folder / f"{Path(model).stem}-dropout{k + 1}.onnx"
        onnx.save(proto, str(path))
        out.append(path)
    return out


def _dense_after_relu(proto: onnx.ModelProto) -> list[tuple[str, bool]]:
    """(weight initializer, whether its input units are columns) of each dense layer whose input is a ReLU of
    another dense layer: where the training run's dropout sat."""
    graph = proto.graph
    producer = {out: node for node in graph.node for out in node.output}
    initializers = {i.name for i in graph.initializer}
    found = []
    for node in graph.node:
        if node.op_type not in ("Gemm", "MatMul") or len(node.input) < 2 or node.input[1] not in initializers:
            continue
        relu = producer.get(node.input[0])
        before = producer.get(relu.input[0]) if relu is not None and relu.op_type == "Relu" else None
        if before is None or before.op_type not in ("Gemm", "MatMul"):
            continue
        trans_b = any(a.name == "transB" and a.i == 1 for a in node.attribute) if node.op_type == "Gemm" else False
        found.append((node.input[1], trans_b))
    if not found:
        raise BadValue("the network has no dense layer after a ReLU dense layer: nothing for MC-dropout to drop out")
    return found
