"""Average several ONNX steering models into one file: the ensemble answers the mean of its members' steering.

Models that err differently on a driver they never saw gain from their mean, which keeps what they agree on
(two seeds of the Unity recipe err much alike: +0.005 of r, docs/experiments.md). The members must read the
same input through the same preprocessing contract, so drive_server decodes and crops the frame once and
the one graph runs every member on it (ONNX ``Mean``). Verified against the members with ONNX Runtime
before the file is kept.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnx import compose, helper

from drive_server.serving.contract import PreprocessContract
from drive_server.serving.settings import SERVING_KEY, Serving
from drive_server.serving.smoothing import NAME, OLD_NAMES
from models.onnxfiles.onnx_metadata import SteeringGraph, read_steering_graph, set_model_metadata
from protocol import runrecords
from protocol.errors import BadValue

TOLERANCE = 1e-4


class EnsembleError(BadValue):
    """The models cannot be averaged into one; the message is one line."""


def _serving(srcs: Sequence[Path], metas: Sequence[dict[str, str]], smoothing: float | None) -> Serving:
    """What the ensemble asks drive_server for: the members' gain (which must agree: the mean of their networks is
    served), and ``smoothing`` if given, else the members' (which must agree)."""
    try:
        members = [Serving.from_json(m.get(SERVING_KEY)) for m in metas]
    except ValueError as exc:
        raise EnsembleError(str(exc)) from None
    gains = {m.gain for m in members}
    if len(gains) > 1:
        raise EnsembleError(f"{srcs[0].name} and the others ask drive_server for different steering gains "
                            f"({', '.join(f'{g:g}' for g in sorted(gains))}): average models served alike")
    gain = gains.pop()
    if smoothing is not None:
        return Serving(smoothing, gain)
    asked = {m.smoothing for m in members}
    if len(asked) > 1:
        raise EnsembleError(f"{srcs[0].name} and the others ask drive_server to smooth differently "
                            f"({', '.join(f'{a:g}' for a in sorted(asked))}): say which with --serve-smooth")
    return Serving(asked.pop(), gain)


def check_members(srcs: Sequence[Path], members: Sequence[SteeringGraph]) -> None:
    """EnsembleError (one line) unless every member reads the first's input through the same preprocessing
    contract and the same ONNX opset (what lets one graph hold them all)."""
    first = members[0]

    def opsets(proto: onnx.ModelProto) -> set[tuple[str, int]]:
        return {(o.domain, o.version) for o in proto.opset_import}

    for src, member in zip(srcs[1:], members[1:], strict=True):
        if member.contract != first.contract or member.shape[1:] != first.shape[1:]:
            raise EnsembleError(f"{src}: its preprocessing differs from {Path(srcs[0]).name}'s; members must read "
                                "the same input")
        if opsets(member.proto) != opsets(first.proto):
            raise EnsembleError(f"{src}: its ONNX opset differs from {Path(srcs[0]).name}'s")


def member_nodes(members: Sequence[SteeringGraph], input_name: str,
                 ) -> tuple[list[onnx.NodeProto], list[onnx.TensorProto], list[str]]:
    """Every member's graph, its names prefixed ``m0_``, ``m1_``..., all reading the one input ``input_name``:
    (nodes, initializers, each member's output name)."""
    nodes: list[onnx.NodeProto] = []
    initializers: list[onnx.TensorProto] = []
    outputs: list[str] = []
    for k, member in enumerate(members):
        prefixed = compose.add_prefix(member.proto, f"m{k}_")
        for node in prefixed.graph.node:  # every member reads the one input
            node.input[:] = [input_name if n == f"m{k}_{member.input_name}" else n for n in node.input]
        nodes.extend(prefixed.graph.node)
        initializers.extend(prefixed.graph.initializer)
        outputs.append(f"m{k}_{member.output_name}")
    return nodes, initializers, outputs


def ensemble_onnx(srcs: Sequence[Path], dst: Path, smoothing: float | None = None, seed: int = 0) -> float:
    """Write ``dst`` (atomically): the mean of ``srcs``' outputs. Return the max |ensemble - mean of members| on
    random inputs (``seed``). ``smoothing`` (< 1 smooths, 1 does not) overrides what the members ask."""
    if len(srcs) < 2:
        raise EnsembleError("an ensemble needs at least two models")
    members = [read_steering_graph(s, EnsembleError) for s in srcs]
    first = members[0]
    check_members(srcs, members)
    serving = _serving(srcs, [m.meta for m in members], smoothing)

    image = next(i for i in first.proto.graph.input if i.name == first.input_name)
    nodes, initializers, outputs = member_nodes(members, first.input_name)
    nodes.append(helper.make_node("Mean", outputs, [first.output_name]))
    graph = helper.make_graph(nodes, "rbc_ensemble", [image], [first.proto.graph.output[0]], initializers)
    out = helper.make_model(graph, opset_imports=list(first.proto.opset_import), ir_version=first.proto.ir_version)

    info = {**first.info, "ensemble": [{"file": Path(s).name, **m.info} for s, m in zip(srcs, members, strict=True)]}
    for key in (NAME, *OLD_NAMES):  # the members' request; set_model_metadata records the ensemble's
        info.pop(key, None)
    set_model_metadata(out, info, serving.smoothing, first.contract, serving.gain)
    onnx.checker.check_model(out)
    with runrecords.atomic_path(Path(dst)) as tmp:
        onnx.save(out, str(tmp))
        worst = _verify(srcs, tmp, first.contract, seed)
    return worst


def _verify(srcs: Sequence[Path], dst: Path, contract: PreprocessContract, seed: int) -> float:
    """The ensemble against the mean of its members on random inputs; EnsembleError beyond ``TOLERANCE``."""
    rng = np.random.default_rng(seed)
    x = (rng.random((2, *contract.input_shape[1:]), dtype=np.float32) - 0.5).astype(np.float32)

    def run(path: Path, batch: np.ndarray) -> np.ndarray:
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        return np.concatenate([session.run(None, {session.get_inputs()[0].name: batch[i:i + 1]})[0].reshape(1, -1)
                               for i in range(len(batch))])

    want = np.mean([run(s, x) for s in srcs], axis=0)
    worst = float(np.abs(run(dst, x) - want).max())
    if not np.isfinite(worst) or worst >= TOLERANCE:
        raise EnsembleError(f"{dst}: the ensemble differs from the mean of its members by {worst:.3g}")
    return worst
