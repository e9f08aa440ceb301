"""Read the peer's Keras 1 ``model.h5`` (naokishibuya/car-behavioral-cloning) for :mod:`models.onnxfiles.peer_keras`.

Only the weights are taken from the file (with h5py; Keras itself is never needed), but only after the layer
configs of its ``model_config`` are checked against the peer's ``model.py`` layer by layer, its input Lambda
against ``x/127.5 - 1`` and every kernel's shape against the architecture: a file that is not the peer's model
fails here with one line naming the first difference, before any network is built.
"""

from __future__ import annotations

import hashlib
import json
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drive_server.serving.contract import PreprocessContract
from protocol.errors import BadValue

if TYPE_CHECKING:
    import h5py

#: The peer's utils.py: crop rows 60..-25 of the 160-row frame, resize to 200x66 (bilinear), then YUV.
PEER_CONTRACT = PreprocessContract(width=200, height=66, crop_top=60, crop_bottom=135, color="rgb",
                                   scale=1.0, offset=0.0, layout="nhwc", interpolation="linear")
#: (class, filters or units, kernel, stride, activation) of every layer of the peer's model.py, in order.
ARCH = (("Lambda",), ("Convolution2D", 24, 5, 2, "elu"), ("Convolution2D", 36, 5, 2, "elu"),
        ("Convolution2D", 48, 5, 2, "elu"), ("Convolution2D", 64, 3, 1, "elu"), ("Convolution2D", 64, 3, 1, "elu"),
        ("Dropout",), ("Flatten",), ("Dense", 100, "elu"), ("Dense", 50, "elu"), ("Dense", 10, "elu"),
        ("Dense", 1, "linear"))


class PeerImportError(BadValue):
    """The file is not the peer's Keras 1 model (message: one line for the user)."""


@dataclass(frozen=True)
class PeerWeights:
    """Kernels as stored by Keras 1 (conv: rows, cols, in, out; dense: in, out) and the file's facts."""

    convs: list[tuple[np.ndarray, np.ndarray]]
    dense: list[tuple[np.ndarray, np.ndarray]]
    keras_version: str
    sha256: str


def read_peer_h5(path: Path) -> PeerWeights:
    """The weights of the peer's Keras 1 HDF5 file, after checking its layers are the peer's architecture."""
    path = Path(path)
    try:
        import h5py
    except ModuleNotFoundError:
        raise PeerImportError('reading Keras .h5 files needs the package h5py (pip install -e ".[peer]")') from None
    if not path.is_file():
        raise PeerImportError(f"{path}: no such file")
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise PeerImportError(f"{path}: not an HDF5 file ({str(exc).splitlines()[0] if str(exc) else 'unreadable'})") \
            from None
    with f:
        version = _text(f.attrs.get("keras_version", "1"))
        if not version.startswith("1"):
            raise PeerImportError(f"{path}: saved by Keras {version}; only Keras 1 files (the peer's) are supported")
        if "model_config" not in f.attrs or "model_weights" not in f:
            raise PeerImportError(f"{path}: not a Keras model file (no model_config and model_weights)")
        try:
            config = json.loads(_text(f.attrs["model_config"]))
            layers = config["config"] if isinstance(config, dict) else None
        except (json.JSONDecodeError, KeyError, TypeError) as exc:
            raise PeerImportError(f"{path}: model_config is not a Keras model config ({exc})") from None
        names = _check_layers(path, layers)
        group = f["model_weights"]
        convs = [_weights(path, group, n, 4) for n in names[1:6]]
        dense = [_weights(path, group, n, 2) for n in names[8:]]
    _check_shapes(path, convs, dense)
    return PeerWeights(convs, dense, version, digest)


def _text(value: object) -> str:
    return value.decode("utf-8") if isinstance(value, bytes) else str(value)


def _check_layers(path: Path, layers: object) -> list[str]:
    """Layer names of a config matching ARCH; PeerImportError naming the first difference."""
    if not isinstance(layers, list) or len(layers) != len(ARCH):
        found = [layer.get("class_name") for layer in layers if isinstance(layer, dict)] if isinstance(layers, list) \
            else layers
        raise PeerImportError(f"{path}: expected the peer's {len(ARCH)} layers "
                              f"({', '.join(a[0] for a in ARCH)}), the file has {found}")
    names = []
    for i, (layer, spec) in enumerate(zip(layers, ARCH, strict=True)):
        cfg = layer.get("config", {}) if isinstance(layer, dict) else {}
        kind = layer.get("class_name") if isinstance(layer, dict) else None
        got: tuple[object, ...]
        if kind == "Convolution2D":
            stride = (cfg.get("subsample") or [1])[0]
            got = (kind, cfg.get("nb_filter"), cfg.get("nb_row"), stride, cfg.get("activation"))
            if cfg.get("nb_col") != cfg.get("nb_row") or list(cfg.get("subsample", [1, 1])) != [got[3]] * 2:
                got = (*got, "non-square")
            if cfg.get("dim_ordering") != "tf" or cfg.get("border_mode") != "valid":
                raise PeerImportError(f"{path}: layer {i + 1} ({cfg.get('name')}) has dim_ordering "
                                      f"{cfg.get('dim_ordering')!r}, border_mode {cfg.get('border_mode')!r}; "
                                      "only the peer's 'tf', 'valid' (TensorFlow-backend kernels) are supported")
        elif kind == "Dense":
            got = (kind, cfg.get("output_dim"), cfg.get("activation"))
        else:
            got = (kind,)
        if got != spec or cfg.get("bias", True) is not True:
            raise PeerImportError(f"{path}: layer {i + 1} ({cfg.get('name')}) is {got}, the peer's model has {spec}")
        names.append(str(cfg.get("name")))
    _check_lambda(path, layers[0].get("config", {}))
    return names


def _check_lambda(path: Path, cfg: dict) -> None:
    """The Lambda's marshalled code must hold the constants 127.5 and 1.0 (x/127.5 - 1) and take 66x200x3."""
    shape = cfg.get("batch_input_shape")
    if list(shape or [])[1:] != [PEER_CONTRACT.height, PEER_CONTRACT.width, 3]:
        raise PeerImportError(f"{path}: the model's input is {shape}, the peer's is [None, 66, 200, 3]")
    function = cfg.get("function")
    code = function[0] if isinstance(function, list) and function else function
    try:
        raw = str(code).encode("raw_unicode_escape")
    except UnicodeEncodeError:
        raw = b""
    if struct.pack("<d", 127.5) not in raw or struct.pack("<d", 1.0) not in raw:
        raise PeerImportError(f"{path}: the input Lambda is not the peer's x/127.5 - 1 normalisation")


def _weights(path: Path, group: h5py.Group, name: str, rank: int) -> tuple[np.ndarray, np.ndarray]:
    if name not in group:
        raise PeerImportError(f"{path}: no weights for layer {name!r} under model_weights/")
    layer = group[name]
    names = [_text(n) for n in layer.attrs.get("weight_names", [])]
    if len(names) != 2 or any(n not in layer for n in names):
        raise PeerImportError(f"{path}: layer {name!r} should hold a kernel and a bias, it holds {names}")
    w, b = (np.asarray(layer[n], dtype=np.float32) for n in names)
    if w.ndim != rank or b.ndim != 1 or b.shape[0] != w.shape[-1]:
        raise PeerImportError(f"{path}: layer {name!r} has kernel {list(w.shape)} and bias {list(b.shape)}")
    if not (np.isfinite(w).all() and np.isfinite(b).all()):
        raise PeerImportError(f"{path}: layer {name!r} holds non-finite weights")
    return w, b


def _check_shapes(path: Path, convs: list[tuple[np.ndarray, np.ndarray]],
                  dense: list[tuple[np.ndarray, np.ndarray]]) -> None:
    channels, height, width = 3, PEER_CONTRACT.height, PEER_CONTRACT.width
    for (w, _), spec in zip(convs, ARCH[1:6], strict=True):
        want = (spec[2], spec[2], channels, spec[1])
        if w.shape != want:
            raise PeerImportError(f"{path}: a convolution kernel is {list(w.shape)}, expected {list(want)} "
                                  "(rows, cols, in, out)")
        channels, height, width = spec[1], (height - spec[2]) // spec[3] + 1, (width - spec[2]) // spec[3] + 1
    features = channels * height * width
    for (w, _), dense_spec in zip(dense, ARCH[8:], strict=True):
        if w.shape != (features, dense_spec[1]):
            raise PeerImportError(f"{path}: a dense kernel is {list(w.shape)}, expected {[features, dense_spec[1]]}")
        features = dense_spec[1]
