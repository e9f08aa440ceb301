"""Import a peer's Keras 1 PilotNet (naokishibuya/car-behavioral-cloning's ``model.h5``) as a served ONNX model.

The peer's network is NVIDIA's PilotNet with ELU activations and an in-model ``x/127.5 - 1``, fed
with the frame's rows 60..135 resized to 200x66 (``cv2.resize``'s default, bilinear) and converted
to YUV. That drive.py ran on OpenCV 3.1, whose 8-bit ``COLOR_RGB2YUV`` was wrong (opencv/opencv
#4946, fixed for 3.2 by #7481): on an RGB image it computed what today's ``COLOR_BGR2YUV`` does,
treating channel 0 as blue. The model was trained and driven with that, so the imported graph takes
RGB (contract colour ``rgb``, no scale) and does the colour conversion itself: the fixed 3x3 matrix
and offset of ``--yuv opencv31`` (or ``correct``, today's RGB-to-YUV) in OpenCV's own fixed-point
form, rounded and saturated as the uint8 ``cvtColor`` is (the network is sensitive to that rounding:
a float conversion moves its steering by up to 0.04), then ``x/127.5 - 1``. Only the weights are
read (h5py), after :mod:`models.onnxfiles.peer_h5` has checked the file's layers against the peer's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from drive_server.serving.preprocess import frame_to_network_image
from models.onnxfiles.peer_h5 import ARCH, PEER_CONTRACT, PeerImportError, PeerWeights, read_peer_h5
from protocol.datalog import read_log
from protocol.jpeg import read_jpeg_file
from protocol.rigfile import REAL_RIG

PEER_REPO = "naokishibuya/car-behavioral-cloning"
PEER_COMMIT = "edf2061"
#: sha256 of the repository's model.h5 at PEER_COMMIT: only that file is credited to the commit.
PEER_H5_SHA256 = "cad4f7c3b837e2b387141fd122f1b13d19c5249031d5f273a60c5b1bf171d3e9"
YUV_MODES = ("opencv31", "correct")

# OpenCV's 8-bit BT.601 RGB->YUV coefficients (fixed point, shift 14; the same in 3.1 and 4.x/5.x)
_ONE, _HALF = 1 << 14, 1 << 13
_R2YI, _G2YI, _B2YI, _B2UI, _R2VI = 4899, 9617, 1868, 8061, 14369
_R2Y, _G2Y, _B2Y, _B2U, _R2V = (c / _ONE for c in (_R2YI, _G2YI, _B2YI, _B2UI, _R2VI))


def yuv_matrix(mode: str) -> tuple[np.ndarray, np.ndarray]:
    """(M, offset) with ``yuv = M @ rgb + offset`` (0..255, before rounding and saturation) for an RGB pixel.

    ``opencv31``: what OpenCV 3.1's COLOR_RGB2YUV gave = today's COLOR_BGR2YUV on RGB (channel 0 as blue);
    ``correct``: today's COLOR_RGB2YUV.
    """
    if mode not in YUV_MODES:
        raise PeerImportError(f"yuv mode must be one of {YUV_MODES}, not {mode!r}")
    red, blue = (2, 0) if mode == "opencv31" else (0, 2)
    y = np.zeros(3)
    y[red], y[1], y[blue] = _R2Y, _G2Y, _B2Y
    u, v = -_B2U * y, -_R2V * y
    u[blue] += _B2U
    v[red] += _R2V
    return np.stack([y, u, v]).astype(np.float32), np.array([0.0, 128.0, 128.0], dtype=np.float32)


class OpenCVYuv(nn.Module):
    """OpenCV's 8-bit RGB->YUV on NCHW RGB 0..255 (integer-valued float), bit for bit: the fixed-point sums,
    their rounding (``Y`` rounded before ``U`` and ``V`` use it) and the saturation of ``cvtColor`` on uint8.

    Every intermediate is an integer below 2**24 and the divisor a power of two, so float32 is exact.
    ``opencv31`` treats channel 0 as blue (today's COLOR_BGR2YUV on RGB), ``correct`` as red (COLOR_RGB2YUV).
    """

    def __init__(self, mode: str) -> None:
        super().__init__()
        yuv_matrix(mode)  # validates the mode
        self.red, self.blue = (2, 0) if mode == "opencv31" else (0, 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        r, g, b = x[:, self.red:self.red + 1], x[:, 1:2], x[:, self.blue:self.blue + 1]
        half, delta = float(_HALF), float(128 * _ONE + _HALF)
        y = torch.floor((r * _R2YI + g * _G2YI + b * _B2YI + half) / _ONE)
        u = torch.floor(((b - y) * _B2UI + delta) / _ONE)
        v = torch.floor(((r - y) * _R2VI + delta) / _ONE)
        return torch.clamp(torch.cat([y, u, v], dim=1), 0.0, 255.0)


class PeerPilotNet(nn.Module):
    """The peer's network on NCHW RGB 0..255: OpenCV's uint8 YUV conversion, x/127.5 - 1, PilotNet with ELU."""

    def __init__(self, weights: PeerWeights, yuv: str) -> None:
        super().__init__()
        self.color = OpenCVYuv(yuv)
        layers: list[nn.Module] = []
        for (w, b), spec in zip(weights.convs, ARCH[1:6], strict=True):
            conv = nn.Conv2d(w.shape[2], w.shape[3], w.shape[0], stride=spec[3])
            _load(conv, w.transpose(3, 2, 0, 1), b)  # TF kernels (rows, cols, in, out); both cross-correlate
            layers += [conv, nn.ELU()]
        self.features = nn.Sequential(*layers)
        channels, height, width = _feature_shape(self.features)
        head: list[nn.Module] = [nn.Flatten()]
        for i, (w, b) in enumerate(weights.dense):
            if i == 0:  # Keras flattened NHWC (h, w, c); this network flattens NCHW (c, h, w)
                w = w.reshape(height, width, channels, -1).transpose(2, 0, 1, 3).reshape(w.shape[0], -1)
            dense = nn.Linear(w.shape[0], w.shape[1])
            _load(dense, w.T, b)
            head += [dense] + ([nn.ELU()] if i < len(weights.dense) - 1 else [])
        self.head = nn.Sequential(*head)  # the Dropout before Flatten is the identity at inference
        for p in self.parameters():
            p.requires_grad_(False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.from_yuv(self.color(x))

    def from_yuv(self, yuv: torch.Tensor) -> torch.Tensor:
        """The Keras model itself, on NCHW YUV 0..255 (the peer's preprocessed image)."""
        return self.head(self.features(yuv / 127.5 - 1.0))


def _load(layer: nn.Conv2d | nn.Linear, w: np.ndarray, b: np.ndarray) -> None:
    with torch.no_grad():
        layer.weight.copy_(torch.from_numpy(np.ascontiguousarray(w, dtype=np.float32)))
        layer.get_parameter("bias").copy_(torch.from_numpy(np.asarray(b, dtype=np.float32)))


def _feature_shape(features: nn.Module) -> tuple[int, int, int]:
    with torch.no_grad():
        out = features(torch.zeros(1, 3, PEER_CONTRACT.height, PEER_CONTRACT.width))
    return int(out.shape[1]), int(out.shape[2]), int(out.shape[3])


def model_info(weights: PeerWeights, h5: Path, yuv: str) -> dict:
    """The ``rbc.model`` metadata of an imported model: where it came from and how it sees colour."""
    ours = weights.sha256 == PEER_H5_SHA256
    return {"arch": "pilotnet (Keras 1, ELU)", "weights": "imported", "source": f"https://github.com/{PEER_REPO}",
            "repository": PEER_REPO, "commit": PEER_COMMIT if ours else "unknown (not the commit's model.h5)",
            "file": Path(h5).name, "h5_sha256": weights.sha256, "keras_version": weights.keras_version,
            "license": "MIT (the peer's repository)" if ours else "unknown", "yuv": yuv,
            "yuv_note": "opencv31: OpenCV 3.1's COLOR_RGB2YUV (= COLOR_BGR2YUV on RGB), what the model was trained "
                        "and driven with" if yuv == "opencv31" else "correct: today's COLOR_RGB2YUV",
            "preprocess": "crop rows 60..135, cv2.resize 200x66 INTER_LINEAR, YUV in the graph, x/127.5 - 1",
            "parameters": int(sum(w.size + b.size for w, b in weights.convs + weights.dense)),
            "camera_rig": REAL_RIG}


def verification_frames(data: Path | None, count: int = 8) -> np.ndarray:
    """Network images (uint8, RGB 66x200) to check the export on: a log's first centre frames, else synthetic."""
    if data is not None:
        samples, _ = read_log(data)
        paths = [s.center for s in samples if s.center is not None][:count]
        if paths:
            return np.stack([frame_to_network_image(read_jpeg_file(p), PEER_CONTRACT) for p in paths])
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, (count, PEER_CONTRACT.height, PEER_CONTRACT.width, 3), dtype=np.uint8)


def import_peer(h5: Path, out: Path, yuv: str = "opencv31", data: Path | None = None) -> tuple[dict, float]:
    """Write ``out`` (ONNX, contract in its metadata); return its model info and the export's max |ORT - torch|."""
    from models.onnxfiles.export import export_onnx

    weights = read_peer_h5(h5)
    info = model_info(weights, h5, yuv)
    net = PeerPilotNet(weights, yuv).eval()
    diff = export_onnx(net, PEER_CONTRACT, info, Path(out), verification_frames(data))
    return info, diff
