"""What a model file says about itself: the ONNX metadata that training, ``rbc mirror`` and ``rbc ensemble``
write, and the one-image-in, one-steering-out graph the latter two rewrite (torch-free)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict, cast

from drive_server.serving.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY, PreprocessContract, infer_contract
from drive_server.serving.settings import GAIN, NO_GAIN, SERVING_KEY, serving_json
from drive_server.serving.smoothing import NAME, OFF, OLD_NAMES

if TYPE_CHECKING:
    import onnx


class ModelInfo(TypedDict, total=False):
    """The keys of a model's record (``rbc.model``) that are read back. Its writers add others (training's figures,
    an imported model's source, an ensemble's members), which the record keeps."""

    arch: str
    behavior: str
    parameters: int  # the network's weights
    camera_rig: str  # the rig its frames were filmed by
    mirror_average: bool  # the file answers the mirror average of the network
    output_scale: float  # a gain an older rbc mirror baked into the graph


@dataclass(frozen=True)
class SteeringGraph:
    """An ONNX steering model as read from its file: the graph and what its metadata says."""

    proto: onnx.ModelProto
    input_name: str
    output_name: str
    shape: tuple[int | str | None, ...]  # the input's dimensions; a name or None where not fixed
    contract: PreprocessContract  # its metadata's, else inferred from the input shape
    meta: dict[str, str]
    info: ModelInfo  # its record (rbc.model), {} if none


def read_steering_graph(src: Path, error: type[ValueError]) -> SteeringGraph:
    """``src`` as a :class:`SteeringGraph`; ``error`` (one line) if it is not ONNX or not one rank-4 image in and
    one steering out."""
    import onnx

    try:
        proto = onnx.load(str(src))
    except Exception as exc:  # not a file, not protobuf, truncated: whatever onnx raises
        first = str(exc).strip().splitlines()[0][:120] if str(exc).strip() else type(exc).__name__
        raise error(f"{src}: not an ONNX model ({first})") from None
    graph = proto.graph
    inputs = [i for i in graph.input if i.name not in {t.name for t in graph.initializer}]
    if len(inputs) != 1 or len(graph.output) != 1:
        raise error(f"{src}: expected one image input and one steering output")
    dims = inputs[0].type.tensor_type.shape.dim
    shape = tuple(d.dim_value if d.HasField("dim_value") else d.dim_param or None for d in dims)
    if len(shape) != 4:
        raise error(f"{src}: the input must have rank 4, not {len(shape)}")
    meta = {p.key: p.value for p in proto.metadata_props}
    try:
        contract = PreprocessContract.from_json(meta[METADATA_KEY]) if METADATA_KEY in meta else infer_contract(shape)
        info = json.loads(meta.get(METADATA_MODEL_INFO_KEY, "{}") or "{}")
    except ValueError as exc:  # json.JSONDecodeError is one
        raise error(f"{src}: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
    return SteeringGraph(proto, inputs[0].name, graph.output[0].name, shape, contract, meta,
                         cast(ModelInfo, info) if isinstance(info, dict) else {})  # a JSON object


def set_model_metadata(proto: onnx.ModelProto, info: Mapping[str, object], smoothing: float = OFF,
                       contract: PreprocessContract | None = None, gain: float = NO_GAIN) -> None:
    """Replace ``proto``'s model info (and its contract, if given) and ask drive_server for ``smoothing`` (< 1)
    and ``gain`` (drive_server.serving.settings); keys the model already carries otherwise stay."""
    meta = {p.key: p.value for p in proto.metadata_props}
    if contract is not None:
        meta[METADATA_KEY] = contract.to_json()
    record = {k: v for k, v in info.items() if k not in (NAME, GAIN, *OLD_NAMES)}  # what is asked is said below
    if smoothing < OFF:  # the model's record says what it asks, as rbc train's does
        record[NAME] = smoothing
    if gain != NO_GAIN:
        record[GAIN] = gain
    meta[METADATA_MODEL_INFO_KEY] = json.dumps(record, sort_keys=True, default=str)
    meta.pop(SERVING_KEY, None)
    if smoothing < OFF or gain != NO_GAIN:
        meta[SERVING_KEY] = serving_json(smoothing, gain)
    del proto.metadata_props[:]
    for key, value in meta.items():
        proto.metadata_props.add(key=key, value=value)
