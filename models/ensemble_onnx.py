"""Average several ONNX steering models into one file: the ensemble answers the mean of its members' steering.

Models trained alike from different seeds err differently on a driver they never saw (each learns its own
idiosyncrasies of the training drivers); their mean keeps what they agree on. The members must read the
same input through the same preprocessing contract, so drive_server decodes and crops the frame once and
the one graph runs every member on it (ONNX ``Mean``). Verified against the members with ONNX Runtime
before the file is kept.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from onnx import compose, helper

from drive_server import runrecords
from drive_server.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY, PreprocessContract, infer_contract
from drive_server.smoothing import SERVING_KEY, serving_alpha
from models.onnx_metadata import set_model_metadata

TOLERANCE = 1e-4


class EnsembleError(ValueError):
    """The models cannot be averaged into one; the message is one line."""


def _load(src: Path) -> onnx.ModelProto:
    try:
        return onnx.load(str(src))
    except Exception as exc:  # not a file, not protobuf, truncated: whatever onnx raises
        first = str(exc).strip().splitlines()[0][:120] if str(exc).strip() else type(exc).__name__
        raise EnsembleError(f"{src}: not an ONNX model ({first})") from None


def _signature(src: Path, proto: onnx.ModelProto) -> tuple[str, str, PreprocessContract, dict[str, str]]:
    """(input name, output name, contract, metadata) of one member; EnsembleError if it is not one image in,
    one steering out."""
    graph = proto.graph
    inputs = [i for i in graph.input if i.name not in {t.name for t in graph.initializer}]
    if len(inputs) != 1 or len(graph.output) != 1:
        raise EnsembleError(f"{src}: expected one image input and one steering output")
    meta = {p.key: p.value for p in proto.metadata_props}
    dims = inputs[0].type.tensor_type.shape.dim
    shape = tuple(d.dim_value if d.HasField("dim_value") else d.dim_param or None for d in dims)
    if len(shape) != 4:
        raise EnsembleError(f"{src}: the input must have rank 4, not {len(shape)}")
    try:
        contract = PreprocessContract.from_json(meta[METADATA_KEY]) if METADATA_KEY in meta else infer_contract(shape)
    except ValueError as exc:
        raise EnsembleError(f"{src}: {exc}") from None
    return inputs[0].name, graph.output[0].name, contract, meta


def _serving(srcs: Sequence[Path], metas: Sequence[dict[str, str]], serve_smooth: float | None) -> float:
    """The smoothing the ensemble asks for: ``serve_smooth`` if given, else the members' (which must agree)."""
    if serve_smooth is not None:
        return serve_smooth
    try:
        asked = {serving_alpha(m.get(SERVING_KEY)) for m in metas}
    except ValueError as exc:
        raise EnsembleError(str(exc)) from None
    if len(asked) > 1:
        raise EnsembleError(f"{srcs[0].name} and the others ask drive_server to smooth differently "
                            f"({', '.join(f'{a:g}' for a in sorted(asked))}): say which with --serve-smooth")
    return asked.pop()


def ensemble_onnx(srcs: Sequence[Path], dst: Path, serve_smooth: float | None = None, seed: int = 0) -> float:
    """Write ``dst`` (atomically): the mean of ``srcs``' outputs. Return the max |ensemble - mean of members| on
    random inputs (``seed``). ``serve_smooth`` (< 1 smooths, 1 does not) overrides what the members ask."""
    if len(srcs) < 2:
        raise EnsembleError("an ensemble needs at least two models")
    protos = [_load(s) for s in srcs]
    sigs = [_signature(s, p) for s, p in zip(srcs, protos, strict=True)]
    contract = sigs[0][2]

    def opsets(proto: onnx.ModelProto) -> set[tuple[str, int]]:
        return {(o.domain, o.version) for o in proto.opset_import}

    for src, proto, sig in zip(srcs[1:], protos[1:], sigs[1:], strict=True):
        if sig[2] != contract:
            raise EnsembleError(f"{src}: its preprocessing differs from {srcs[0].name}'s; members must read the "
                                "same input")
        if opsets(proto) != opsets(protos[0]):
            raise EnsembleError(f"{src}: its ONNX opset differs from {srcs[0].name}'s")
    alpha = _serving(srcs, [s[3] for s in sigs], serve_smooth)

    image_name, steering_name = sigs[0][0], sigs[0][1]
    image = next(i for i in protos[0].graph.input if i.name == image_name)
    steering = protos[0].graph.output[0]
    nodes, initializers, outputs = [], [], []
    for k, (proto, (member_in, member_out, _, _)) in enumerate(zip(protos, sigs, strict=True)):
        prefixed = compose.add_prefix(proto, f"m{k}_")
        for node in prefixed.graph.node:  # every member reads the one input
            node.input[:] = [image_name if n == f"m{k}_{member_in}" else n for n in node.input]
        nodes.extend(prefixed.graph.node)
        initializers.extend(prefixed.graph.initializer)
        outputs.append(f"m{k}_{member_out}")
    nodes.append(helper.make_node("Mean", outputs, [steering_name]))
    graph = helper.make_graph(nodes, "rbc_ensemble", [image], [steering], initializers)
    out = helper.make_model(graph, opset_imports=list(protos[0].opset_import), ir_version=protos[0].ir_version)

    infos = [json.loads(s[3].get(METADATA_MODEL_INFO_KEY, "{}") or "{}") for s in sigs]
    info = {**(infos[0] if isinstance(infos[0], dict) else {}),
            "ensemble": [{"file": Path(s).name, **(i if isinstance(i, dict) else {})} for s, i in zip(srcs, infos,
                                                                                                    strict=True)]}
    info.pop("serve_smooth", None)  # the members' request; set_model_metadata records the ensemble's
    set_model_metadata(out, info, alpha, contract)
    onnx.checker.check_model(out)
    with runrecords.atomic_path(Path(dst)) as tmp:
        onnx.save(out, str(tmp))
        worst = _verify(srcs, tmp, contract, seed)
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
