"""THE JPEG decode used by serving (telemetry frames) and training (recorded frames), and the encoder.

One function decides how a camera frame becomes pixels (flags, reduced-size decode, size check,
channel order), so a model is trained on exactly the pixels the drive server feeds it.
"""

from __future__ import annotations

import base64
import binascii
from pathlib import Path

import cv2
import numpy as np

from protocol.errors import ProtocolError
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH, IMAGE_MAGIC, JPEG_QUALITY
from protocol.jpeg_header import require_size

#: libjpeg's reduced-size decodes: ``reduce`` -> OpenCV flag.
_REDUCE_FLAGS = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
                 8: cv2.IMREAD_REDUCED_COLOR_8}


def decode_jpeg(raw: bytes | bytearray | memoryview | np.ndarray, reduce: int = 1, what: str = "image") -> np.ndarray:
    """Decode a 320x160 JPEG (or PNG) to an RGB ``uint8`` array (160/reduce, 320/reduce, 3).

    ``reduce`` in (1, 2, 4, 8) asks libjpeg to decode at 1/reduce size directly, which is cheaper
    than decoding full size and resizing. ``what`` names the source in error messages.
    """
    if reduce not in _REDUCE_FLAGS:
        raise ValueError(f"reduce must be 1, 2, 4 or 8, not {reduce}")
    data = raw.tobytes() if isinstance(raw, np.ndarray) else bytes(raw)  # bytes(bytes) is no copy
    if not data.startswith(IMAGE_MAGIC):
        raise ProtocolError(f"{what}: not a JPEG (starts with {data[:4]!r}, {len(data)} bytes)", field="image")
    require_size(data, FRAME_WIDTH, FRAME_HEIGHT, what)  # a decompression bomb is refused before decoding
    buf = np.frombuffer(data, np.uint8)
    bgr = cv2.imdecode(buf, _REDUCE_FLAGS[reduce])
    if bgr is None:
        raise ProtocolError(f"{what}: corrupt JPEG ({buf.size} bytes)", field="image")
    if bgr.shape[:2] != (FRAME_HEIGHT // reduce, FRAME_WIDTH // reduce):
        raise ProtocolError(f"{what}: expected {FRAME_WIDTH}x{FRAME_HEIGHT}, "
                            f"got {bgr.shape[1] * reduce}x{bgr.shape[0] * reduce}", field="image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def decode_image(image_b64: str, reduce: int = 1) -> np.ndarray:
    """Decode a telemetry frame (base64 JPEG) to RGB ``uint8``: :func:`decode_jpeg` after base64."""
    try:
        raw = base64.b64decode(image_b64, validate=False)
    except (binascii.Error, ValueError) as exc:
        raise ProtocolError(f"image: invalid base64 ({exc})", field="image") from None
    return decode_jpeg(raw, reduce)


def read_jpeg_file(path: Path, reduce: int = 1) -> np.ndarray:
    """Decode a recorded frame file with :func:`decode_jpeg` (``OSError`` if it cannot be read)."""
    return decode_jpeg(Path(path).read_bytes(), reduce, what=str(path))


def encode_jpeg(rgb: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """JPEG bytes of an RGB frame (quality 75, like Unity's ``EncodeToJPG``)."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ProtocolError("image: JPEG encoding failed", field="image")
    return buf.tobytes()


def encode_image(rgb: np.ndarray, quality: int = JPEG_QUALITY) -> str:
    """Base64 JPEG of an RGB frame, as it goes into a telemetry payload."""
    return base64.b64encode(encode_jpeg(rgb, quality)).decode("ascii")
