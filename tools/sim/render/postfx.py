"""The camera's image processing per world (track ``appearance``): tone, blur, sensor noise, per-frame jitter.

A model trained on one look overfits to it; varying exposure, contrast, white balance, sharpness and
noise per world (and a little per frame) is the cheap part of domain randomisation. Everything is a
few OpenCV calls on the finished 320x160 frame: tone is one table lookup for all three adjustments,
noise adds one of a few precomputed noise tiles at a seeded offset and strength (drawing fresh
Gaussian noise per frame would cost more than the whole render). Per-frame draws come from a
generator seeded by the run, so frames are deterministic per seed.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH
from tools.sim.track.looks import Appearance

NOISE_TILES = 8
NOISE_UNIT = 16.0  # grey levels of one standard deviation in the stored tiles
NOISE_PAD = 32  # extra rows per tile: each frame starts at a random row


def tone_lut(exposure_ev: float, contrast: float, gains: tuple[float, float, float] | np.ndarray) -> np.ndarray:
    """(1, 256, 3) uint8 table: exposure (stops) and white-balance gains, then contrast about mid-grey."""
    x = np.arange(256, dtype=np.float64)[:, None] / 255.0
    y = x * (2.0 ** exposure_ev) * np.asarray(gains, np.float64)[None, :]
    y = (y - 0.5) * contrast + 0.5
    return np.clip(np.round(y * 255.0), 0, 255).astype(np.uint8)[None]


class PostFx:
    """Applies one world's appearance to frames; ``active`` is False for version-1 looks (frames untouched)."""

    def __init__(self, look: Appearance, seed: int = 0) -> None:
        self.look = look
        self.active = look.postprocessed
        self.rng = np.random.default_rng([int(seed), 0x5EED])
        self._lut = tone_lut(look.exposure_ev, look.contrast, look.white_balance) if look.tone_mapped else None
        self._tiles = None
        if look.noise > 0 or look.jitter.noise > 0:
            g = np.random.default_rng([int(seed), look.seed, 0x401])
            n = g.standard_normal((NOISE_TILES, FRAME_HEIGHT + NOISE_PAD, FRAME_WIDTH, 3)) * NOISE_UNIT + 128
            self._tiles = np.clip(np.round(n), 0, 255).astype(np.uint8)
        self._ksize = 3 if look.blur <= 0.8 else 5
        #: rows beyond a pixel's own that its processed value reads (the blur's reach; the rest is per pixel)
        self.margin = self._ksize // 2 if look.blur > 0.05 else 0

    def apply(self, rgb: np.ndarray) -> np.ndarray:
        """The processed frame (a new array or ``rgb`` changed in place)."""
        look, j = self.look, self.look.jitter
        lut = self._lut
        if j.exposure_ev or j.contrast or j.white_balance:
            d = self.rng.standard_normal(5)
            gains = np.asarray(look.white_balance) * (1.0 + j.white_balance * d[2:5])
            lut = tone_lut(look.exposure_ev + j.exposure_ev * d[0], look.contrast * (1.0 + j.contrast * d[1]), gains)
        if lut is not None:
            rgb = cv2.LUT(rgb, lut)
        if look.blur > 0.05:
            rgb = cv2.GaussianBlur(rgb, (self._ksize, self._ksize), look.blur)
        if self._tiles is not None:
            sigma = look.noise + (abs(float(self.rng.standard_normal())) * j.noise if j.noise else 0.0)
            if sigma > 0:
                k = int(self.rng.integers(NOISE_TILES))
                o = int(self.rng.integers(NOISE_PAD))
                w = sigma / NOISE_UNIT
                rgb = cv2.addWeighted(rgb, 1.0, self._tiles[k, o:o + FRAME_HEIGHT], w, -128.0 * w)
        return rgb


def describe(look: Appearance) -> str:
    """One line for logs and contact sheets."""
    wb = look.white_balance
    return (f"EV {look.exposure_ev:+.2f}, contrast {look.contrast:.2f}, WB {wb[0]:.2f}/{wb[1]:.2f}/{wb[2]:.2f}, "
            f"haze x{look.haze:.2f}, blur {look.blur:.2f}, noise {look.noise:.1f}, JPEG q{look.jpeg_quality}"
            + ("" if math.isclose(look.grain, 1.0) else f", grain x{look.grain:.2f}"))
