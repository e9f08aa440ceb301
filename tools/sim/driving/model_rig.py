"""Which camera rig the headless simulator shows a model: the one whose frames it learnt from.

``rbc train`` stamps the rig of its data into the model's record (``camera_rig`` in the ONNX
metadata; :mod:`protocol.rigfile`). A model of ours without it predates the unity rig and learnt
classic frames; a model from elsewhere (no record of ours) most likely learnt the real simulator's.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from drive_server.serving.contract import METADATA_MODEL_INFO_KEY
from tools.sim.render.camera import DEFAULT_RIG, LEGACY_RIG, RIGS

log = logging.getLogger(__name__)


def model_rig(path: str | Path) -> str:
    """The camera rig ``path`` (an ONNX model) was trained on; :data:`DEFAULT_RIG` when it cannot say."""
    import onnxruntime as ort

    try:
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        raw = session.get_modelmeta().custom_metadata_map.get(METADATA_MODEL_INFO_KEY)
        info = json.loads(raw) if raw is not None else None
    except Exception as exc:  # noqa: BLE001 -- the model's own loader reports a bad file; here: the default
        log.debug("%s: no model record readable (%s); camera %s", path, exc, DEFAULT_RIG)
        return DEFAULT_RIG
    if not isinstance(info, dict):
        return DEFAULT_RIG
    rig = info.get("camera_rig", LEGACY_RIG)
    return rig if rig in RIGS else DEFAULT_RIG  # "" (data of several rigs): the default


def resolve_rig(requested: str | None, model: str | Path | None) -> str:
    """``--camera`` as given, else the model's rig, else (no model: the autopilot, a server) the default."""
    if requested:
        return requested
    return model_rig(model) if model is not None else DEFAULT_RIG
