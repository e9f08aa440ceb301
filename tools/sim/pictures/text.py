"""Readable text on pictures: Pillow's bundled open font (Aileron, SIL OFL) instead of OpenCV's Hershey strokes.

OpenCV's vector font smears at the small sizes a contact sheet or a camera overlay needs; Pillow ships
a real anti-aliased TrueType face, so every picture of the project draws its words through here.
Works on BGR and RGB arrays alike (colours are given in the array's own channel order).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from PIL import Image, ImageDraw, ImageFont


@lru_cache(maxsize=16)
def font(px: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    return ImageFont.load_default(size=px)


def text_size(text: str, px: int) -> tuple[int, int]:
    left, top, right, bottom = font(px).getbbox(text)
    return int(right - left), int(bottom - top)


def draw_text(img: np.ndarray, text: str, org: tuple[int, int], px: int = 14,
              color: tuple[int, int, int] = (235, 235, 235), box: bool = False) -> None:
    """Write ``text`` with its baseline starting at ``org`` (x, y), in place; ``box`` darkens a plate behind it."""
    x, y = org
    w, h = text_size(text, px)
    pad = max(2, px // 5)
    x0, y0 = max(0, x - pad), max(0, y - h - pad)
    x1, y1 = min(img.shape[1], x + w + pad), min(img.shape[0], y + pad + px // 4)
    if x1 <= x0 or y1 <= y0:
        return
    patch = img[y0:y1, x0:x1]
    if box:
        patch[:] = (patch * 0.35).astype(np.uint8)
    canvas = Image.fromarray(np.ascontiguousarray(patch))
    ImageDraw.Draw(canvas).text((x - x0, y - y0), text, font=font(px), fill=tuple(int(c) for c in color),
                                anchor="ls")
    patch[:] = np.asarray(canvas)
