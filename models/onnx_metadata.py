"""What a model file says about itself: the ONNX metadata that training and ``rbc mirror`` write (torch-free)."""

from __future__ import annotations

import json
from typing import Any

from drive_server.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY, PreprocessContract
from drive_server.smoothing import OFF, SERVING_KEY, serving_json


def set_model_metadata(proto: Any, info: dict[str, Any], serve_smooth: float = OFF,
                       contract: PreprocessContract | None = None) -> None:
    """Replace ``proto``'s model info (and its contract, if given) and ask for ``serve_smooth`` (< 1); keys the
    model already carries otherwise stay."""
    meta = {p.key: p.value for p in proto.metadata_props}
    if contract is not None:
        meta[METADATA_KEY] = contract.to_json()
    if serve_smooth < OFF:  # the model's record says what it asks, as rbc train's does
        info = {**info, "serve_smooth": serve_smooth}
    meta[METADATA_MODEL_INFO_KEY] = json.dumps(info, sort_keys=True, default=str)
    if serve_smooth < OFF:
        meta[SERVING_KEY] = serving_json(serve_smooth)
    del proto.metadata_props[:]
    for key, value in meta.items():
        proto.metadata_props.add(key=key, value=value)
