"""THE preprocessing function, shared by training (``models``) and serving (``drive_server``).

Split in two so training can batch the cheap pointwise half:
``frame_to_network_image`` (crop, resize, colour; uint8) and ``to_input_tensor`` (scale, offset,
layout; float32). ``preprocess`` composes both for one frame.
"""

from __future__ import annotations

import cv2
import numpy as np

from drive_server.serving.contract import PreprocessContract
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH

_INTERP = {"area": cv2.INTER_AREA, "linear": cv2.INTER_LINEAR}


def jpeg_reduction(contract: PreprocessContract) -> int:
    """Largest libjpeg decode scale (1, 2, 4, 8) that still leaves at least the network's resolution.

    Decoding a 320x160 JPEG at half size costs about 60 % of a full decode. The 64x64 input then
    differs from a full-size decode by about 2.7/255 on average (libjpeg's DCT scaling is not an
    exact box filter), which is why training decodes with this same rule: the network is trained
    on exactly the pixels it is served. A contract's own ``decode_reduce`` overrides the rule.
    """
    if contract.decode_reduce:
        return contract.decode_reduce
    crop_h = contract.crop_bottom - contract.crop_top
    for r in (8, 4, 2):
        if FRAME_WIDTH // r >= contract.width and crop_h // r >= contract.height and contract.crop_top % r == 0 \
                and contract.crop_bottom % r == 0:
            return r
    return 1


def frame_to_network_image(rgb: np.ndarray, contract: PreprocessContract) -> np.ndarray:
    """Crop, resize and colour-convert one RGB frame (any decode scale) to the network's size, uint8."""
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an RGB image (H, W, 3), got shape {rgb.shape}")
    scale = rgb.shape[0] / FRAME_HEIGHT
    top, bottom = round(contract.crop_top * scale), round(contract.crop_bottom * scale)
    if top or bottom != rgb.shape[0]:
        rgb = rgb[top:bottom]
    out = cv2.resize(rgb, (contract.width, contract.height), interpolation=_INTERP[contract.interpolation])
    if contract.color == "yuv":
        out = cv2.cvtColor(out, cv2.COLOR_RGB2YUV)
    elif contract.color == "bgr":
        out = out[..., ::-1]
    return np.ascontiguousarray(out)


def blank_edges(images: np.ndarray, columns: int) -> np.ndarray:
    """In place: the outer ``columns`` columns on each side of (N, H, W, C) images repeat the next one inward."""
    if columns:
        images[:, :, :columns] = images[:, :, columns:columns + 1]
        images[:, :, -columns:] = images[:, :, -columns - 1:-columns]
    return images


def to_input_tensor(images: np.ndarray, contract: PreprocessContract) -> np.ndarray:
    """Scale/offset a uint8 batch (N, H, W, 3) or one image (H, W, 3) to float32 in the contract's layout
    (after repeating the edge columns a ``blank_columns`` contract asks for)."""
    if images.ndim == 3:
        images = images[None]
    x = images.astype(np.float32)
    blank_edges(x, contract.blank_columns)  # every input of the network passes here: serving, training, validation
    x *= np.float32(contract.scale)
    x += np.float32(contract.offset)
    if contract.layout == "nchw":
        x = np.ascontiguousarray(x.transpose(0, 3, 1, 2))
    return x


def preprocess(rgb: np.ndarray, contract: PreprocessContract) -> np.ndarray:
    """One camera frame (RGB uint8, full or reduced decode) -> the network's float32 input, batch 1."""
    return to_input_tensor(frame_to_network_image(rgb, contract), contract)
