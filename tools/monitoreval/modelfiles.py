"""The model files a benchmark run drives besides the served one: copies with weight noise and under-trained
checkpoints, each carrying the served file's monitor, named and cached by content so a run is keyed by what it
drove."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from protocol.errors import BadValue

if TYPE_CHECKING:
    import onnx

#: The two halves of a mirror-averaged graph (``rbc mirror``): f(x) and f(x mirrored); steering = (a - b) / 2.
MIRROR_HALVES = ("rbc_mirror_first", "rbc_mirror_second")


def file_digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def degraded_model(src: Path, folder: Path, sigma: float, seed: int = 0) -> Path:
    """``src`` with Gaussian noise on every weight tensor (sigma times the tensor's std), its metadata and monitor
    kept: a model that drives worse on the same frames. Cached in ``folder`` by source content, sigma and seed."""
    import onnx
    from onnx import numpy_helper

    from protocol.runrecords import atomic_path

    dst = Path(folder) / f"{Path(src).stem}-noise{sigma:g}-s{seed}-{file_digest(src)}.onnx"
    if dst.is_file():
        return dst
    rng = np.random.default_rng(seed)
    proto = onnx.load(str(src))
    for tensor in proto.graph.initializer:
        w = numpy_helper.to_array(tensor)
        if w.dtype != np.float32 or w.size < 2:
            continue
        noisy = (w + rng.normal(0.0, sigma * float(w.std()), w.shape)).astype(np.float32)
        tensor.CopyFrom(numpy_helper.from_array(noisy, tensor.name))
    with atomic_path(dst) as tmp:
        onnx.save(proto, str(tmp))
    return dst


def check_checkpoint(served: Path, checkpoint: Path) -> None:
    """BadValue (one line) unless ``checkpoint`` can stand in for ``served`` under its monitor: another file that
    reads the same input (preprocessing contract ``rbc.preprocess``, input shape, camera rig), answers the mirror
    average alike (graph outputs :data:`MIRROR_HALVES`) and asks for the same serving
    settings (``rbc.serving``: gain, smoothing)."""
    from drive_server.serving.settings import SERVING_KEY, Serving
    from models.onnxfiles.onnx_metadata import read_steering_graph
    from tools.sim.driving.model_rig import model_rig

    name, hint = Path(checkpoint).name, "give a checkpoint of the served model's recipe, exported and mirrored alike"
    if file_digest(checkpoint) == file_digest(served):
        raise BadValue(f"checkpoint {name}: the served model {Path(served).name} itself", hint)
    a, b = read_steering_graph(served, BadValue), read_steering_graph(checkpoint, BadValue)
    if b.contract != a.contract or b.shape[1:] != a.shape[1:]:
        raise BadValue(f"checkpoint {name}: its preprocessing (rbc.preprocess, input shape) differs from "
                       f"{Path(served).name}'s", hint)
    if model_rig(checkpoint) != model_rig(served):
        raise BadValue(f"checkpoint {name}: trained for the {model_rig(checkpoint)} camera, {Path(served).name} for "
                       f"the {model_rig(served)} camera", hint)

    def mirrored(proto: onnx.ModelProto) -> bool:
        return set(MIRROR_HALVES) <= {out for node in proto.graph.node for out in node.output}

    if mirrored(a.proto) != mirrored(b.proto):
        raise BadValue(f"checkpoint {name}: {'answers' if mirrored(b.proto) else 'does not answer'} the mirror "
                       f"average and {Path(served).name} {'does not' if mirrored(b.proto) else 'does'}",
                       "treat it as the served model was (rbc mirror)")
    try:
        settings = [Serving.from_json(g.meta.get(SERVING_KEY)) for g in (a, b)]
    except BadValue as exc:
        raise BadValue(f"checkpoint {name} or {Path(served).name}: {exc}") from None
    if settings[0] != settings[1]:
        raise BadValue(f"checkpoint {name}: served with {settings[1].describe() or 'nothing asked'}, "
                       f"{Path(served).name} with {settings[0].describe() or 'nothing asked'}", hint)


def checkpoint_epochs(checkpoint: Path) -> float:
    """How many epochs ``checkpoint`` was trained (its record's exported epoch, else its epochs); 0 if it cannot
    say."""
    from models.onnxfiles.onnx_metadata import read_steering_graph

    info = read_steering_graph(checkpoint, BadValue).info
    for key in ("exported_epoch", "epochs"):
        value = info.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
    return 0.0


def undertrained_model(checkpoint: Path, served: Path, folder: Path) -> Path:
    """``checkpoint`` (checked by :func:`check_checkpoint`) carrying the served model's monitor: every ``rbc.monitor``
    metadata key of ``served`` in place of any the checkpoint has, the rest of the checkpoint as it is. Cached in
    ``folder`` by both files' content, so a run of it is keyed by the checkpoint's content and the monitor's."""
    import onnx

    from drive_server.serving.monitor import MONITOR_KEY
    from protocol.runrecords import atomic_path

    check_checkpoint(served, checkpoint)
    dst = Path(folder) / f"{Path(checkpoint).stem}-watched-{file_digest(checkpoint)}-{file_digest(served)}.onnx"
    if dst.is_file():
        return dst

    def monitor_key(key: str) -> bool:
        return key == MONITOR_KEY or key.startswith(MONITOR_KEY + ".")

    proto = onnx.load(str(checkpoint))
    served_meta = [(m.key, m.value) for m in onnx.load(str(served)).metadata_props if monitor_key(m.key)]
    kept = [(m.key, m.value) for m in proto.metadata_props if not monitor_key(m.key)]
    del proto.metadata_props[:]
    for key, value in kept + served_meta:
        proto.metadata_props.add(key=key, value=value)
    dst.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(dst) as tmp:
        onnx.save(proto, str(tmp))
    return dst
