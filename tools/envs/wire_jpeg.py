"""The environment's decode of its own wire JPEGs: protocol.jpeg's pixels, at libjpeg-turbo's speed.

Every step of a JPEG observation decodes one frame. OpenCV's ``imdecode`` spends about 0.1 ms of its 0.26 ms per
320x160 frame outside libjpeg-turbo (finding the codec, copying, the BGR order; measured on 2 cores), while
``simplejpeg`` (the gym extra) calls libjpeg-turbo's decoder directly: 0.17 ms. Both run the library's defaults
(the exact integer IDCT, fancy upsampling), so the pixels are the same; :func:`wire_decoder` checks that on a probe
frame at every scale and otherwise keeps :func:`protocol.jpeg.decode_jpeg`, THE decode drive_server uses. Only the
environment's own frames pass here (encoded a moment before): the wire's size and corruption checks stay
protocol.jpeg's, for frames from outside.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from functools import cache

import numpy as np

from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH
from protocol.jpeg import decode_jpeg, encode_jpeg

log = logging.getLogger(__name__)

Decoder = Callable[[bytes, int], np.ndarray]  # (JPEG bytes, reduce 1/2/4/8) -> RGB uint8


def _probe_frame() -> np.ndarray:
    """A 320x160 frame with edges, gradients and saturated colours: where IDCT or upsampling differences show."""
    y, x = np.mgrid[0:FRAME_HEIGHT, 0:FRAME_WIDTH]
    rgb = np.stack([x * 255 // (FRAME_WIDTH - 1), y * 255 // (FRAME_HEIGHT - 1), ((x // 8 + y // 8) % 2) * 255], -1)
    rgb[40:90, 100:180] = (230, 40, 20)
    return rgb.astype(np.uint8)


def _simplejpeg_decode(data: bytes, reduce: int = 1) -> np.ndarray:
    import simplejpeg

    if reduce == 1:
        return simplejpeg.decode_jpeg(data, colorspace="RGB")
    return simplejpeg.decode_jpeg(data, colorspace="RGB", min_width=FRAME_WIDTH // reduce,
                                  min_height=FRAME_HEIGHT // reduce)


@cache
def wire_decoder() -> Decoder:
    """simplejpeg's decode where it is installed and gives protocol.jpeg's pixels; else protocol.jpeg's."""
    try:
        import simplejpeg  # noqa: F401
    except ImportError:
        return decode_jpeg
    data = encode_jpeg(_probe_frame())
    try:
        same = all(np.array_equal(_simplejpeg_decode(data, r), decode_jpeg(data, r)) for r in (1, 2, 4, 8))
    except (ValueError, RuntimeError) as exc:  # an unusual build: keep the reference decode
        log.debug("simplejpeg failed on the probe frame (%s): decoding with OpenCV", exc)
        return decode_jpeg
    if not same:
        log.debug("simplejpeg's pixels differ from OpenCV's on the probe frame: decoding with OpenCV")
        return decode_jpeg
    return _simplejpeg_decode
