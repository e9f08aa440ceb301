"""Top-down ground albedo of a track: grass or forest floor, water, shoulders, road surfaces and markings.

The renderer draws the ground by inverse perspective mapping of this one texture (5 cm per texel by
default), so everything flat -- lines, kerbs, bridge planks, ponds -- is painted here once per track,
with OpenCV polygon fills (C++ speed, anti-aliased) rather than per-texel NumPy work. Lighting is
not applied here: :mod:`tools.sim.render.world` multiplies this albedo by a light map per sun direction.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from tools.sim.render.road_paint import SHIFT, paint_road
from tools.sim.track.road import Track
from tools.sim.track.themes import PALETTES

log = logging.getLogger(__name__)

TEXEL_M = 0.05  # preferred ground texture resolution, metres per texel
MAX_TEXELS = 48_000_000  # bigger tracks get coarser texels rather than an unbounded texture
MAX_SIDE = 30_000  # texels; cv2.remap addresses sources with 16-bit coordinates
MARGIN_M = 25.0  # ground painted beyond the outermost road edge; further out is a flat mean colour


@dataclass(frozen=True, eq=False)
class GroundAlbedo:
    """RGB albedo image of the ground; texel (u, v) covers world x = x0 + u*res, y = y1 - v*res."""

    rgb: np.ndarray  # (H, W, 3) uint8
    x0: float
    y1: float
    res: float
    mean_rgb: tuple[int, int, int]  # colour of the ground beyond the texture
    water: np.ndarray  # (H // 8, W // 8) uint8 mask at 8x coarser resolution, 255 = water

    @property
    def shape(self) -> tuple[int, int]:
        return self.rgb.shape[:2]

    def to_texel(self, xy: np.ndarray) -> np.ndarray:
        """World metres (..., 2) -> float texel coordinates (..., 2)."""
        xy = np.asarray(xy, dtype=np.float64)
        return np.stack([(xy[..., 0] - self.x0) / self.res, (self.y1 - xy[..., 1]) / self.res], -1)

    def is_water(self, xy: np.ndarray) -> np.ndarray:
        uv = (self.to_texel(xy) / 8).astype(np.int64)
        h, w = self.water.shape
        inside = (uv[..., 0] >= 0) & (uv[..., 0] < w) & (uv[..., 1] >= 0) & (uv[..., 1] < h)
        out = np.zeros(uv.shape[:-1], bool)
        out[inside] = self.water[uv[inside][:, 1], uv[inside][:, 0]] > 127
        return out


def fbm(shape: tuple[int, int], rng: np.random.Generator, cells: tuple[int, ...] = (4, 12, 40),
        amps: tuple[float, ...] = (1.0, 0.5, 0.25)) -> np.ndarray:
    """Smooth value noise in about [-1, 1]: a sum of upsampled random grids (cheap, seedable)."""
    h, w = shape
    out = np.zeros((h, w), np.float32)
    for c, a in zip(cells, amps, strict=True):
        gw = max(2, c)
        gh = max(2, int(round(c * h / max(w, 1))))
        grid = rng.standard_normal((gh, gw)).astype(np.float32)
        out += a * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
    return out / max(float(np.abs(out).max()), 1e-6)


def palette(track: Track) -> dict[str, tuple[int, int, int]]:
    """The theme's palette with the track's own overrides (``appearance.palette``)."""
    return {**PALETTES[track.scenery.theme], **dict(track.appearance.palette)}


def paint_ground(track: Track, seed: int | None = None) -> GroundAlbedo:
    """Paint the albedo texture of ``track`` (deterministic for a track and seed; default: the track's)."""
    look = track.appearance
    rng = np.random.default_rng(look.seed if seed is None else seed)
    pal = palette(track)
    reach = track.road_width / 2 + track.shoulder_width + MARGIN_M
    lo = track.centerline.min(0) - reach
    hi = track.centerline.max(0) + reach
    area = float(np.prod(hi - lo))
    res = max(TEXEL_M, math.sqrt(area / MAX_TEXELS), float((hi - lo).max()) / MAX_SIDE)
    if res > TEXEL_M:
        # info, not a warning: expected for large generated worlds (5-7 cm), and nothing the user must fix
        log.info("track %s spans %.0f x %.0f m: ground texture coarsened to %.1f cm per texel",
                    track.name, *(hi - lo), res * 100)
    w = int(math.ceil((hi[0] - lo[0]) / res / 8)) * 8
    h = int(math.ceil((hi[1] - lo[1]) / res / 8)) * 8
    x0, y1 = float(lo[0]), float(hi[1])

    # 1. large-scale ground colour at 8x coarser resolution, faded to the mean colour towards the border
    ch, cw = h // 8, w // 8
    if look.texture_scale == 1.0:
        n1, n2 = fbm((ch, cw), rng), fbm((ch, cw), rng, cells=(6, 24, 90))
    else:  # bigger blotches: fewer noise cells over the same texture
        k = look.texture_scale
        n1 = fbm((ch, cw), rng, cells=tuple(max(2, round(c / k)) for c in (4, 12, 40)))
        n2 = fbm((ch, cw), rng, cells=tuple(max(2, round(c / k)) for c in (6, 24, 90)))
    mix = np.clip(0.5 + 0.6 * n1, 0, 1)[..., None]
    base = (1 - mix) * np.array(pal["ground"], np.float32) + mix * np.array(pal["ground2"], np.float32)
    base *= (1.0 + 0.12 * n2)[..., None]
    mean = base.reshape(-1, 3).mean(0)
    edge = min(15.0 / (res * 8), min(ch, cw) / 4)
    yy, xx = np.mgrid[0:ch, 0:cw]
    dist = np.minimum(np.minimum(xx, cw - 1 - xx), np.minimum(yy, ch - 1 - yy)).astype(np.float32)
    fade = np.clip(dist / edge, 0, 1)[..., None]
    base = fade * base + (1 - fade) * mean
    img = cv2.resize(np.clip(base, 0, 255).astype(np.uint8), (w, h), interpolation=cv2.INTER_LINEAR)

    # 2. water: a muddy shore ring, then the water itself (full resolution for a crisp shoreline)
    water = np.zeros((ch, cw), np.uint8)
    for target, scale, pad, color in ((img, 1, 2.0, pal["shore"]), (img, 1, 0.0, pal["water"]), (water, 8, 0.0, 255)):
        for spec in track.scenery.water:
            ctr = ((spec.center[0] - x0) / res / scale, (y1 - spec.center[1]) / res / scale)
            axes = tuple(int((r + pad) / res / scale * (1 << SHIFT)) for r in spec.radius)
            centre = tuple(int(v * (1 << SHIFT)) for v in ctr)
            cv2.ellipse(target, centre, axes, -spec.angle_deg, 0, 360, color, -1, cv2.LINE_AA, SHIFT)

    # 3. the road (tools.sim.render.road_paint)
    paint_road(track, img, x0, y1, res, pal, np.random.default_rng([track.appearance.seed, 1]))

    # 4. fine grain everywhere (a tiled noise patch; the large-scale colour hides the 25 m period)
    tile = (rng.standard_normal((512, 512, 1)) * 7 + rng.standard_normal((512, 512, 3)) * 3
            + cv2.resize(rng.standard_normal((128, 128)).astype(np.float32), (512, 512))[..., None] * 5)
    add_grain(img, np.clip(tile + 32, 0, 64).astype(np.uint8), look.grain)
    red, green, blue = (int(v) for v in np.clip(mean, 0, 255))
    return GroundAlbedo(rgb=img, x0=x0, y1=y1, res=res, mean_rgb=(red, green, blue), water=water)


def add_grain(img: np.ndarray, tile: np.ndarray, strength: float) -> None:
    """In place: ``img + strength * (grain - 32)``, the grain ``tile`` repeated over the image, saturated to uint8.

    A band of the tile's height at a time: the same pixels as one ``cv2.addWeighted`` with the whole repeated
    grain, without two more textures in memory at once (a lake's albedo is 128 MB). Each band is added into a new
    array and copied back: OpenCV's in-place ``dst=`` rounds some row ends differently."""
    h, w = img.shape[:2]
    rows = tile.shape[0]
    grain = cv2.repeat(tile, 1, w // tile.shape[1] + 1)[:, :w]
    for top in range(0, h, rows):
        band = img[top:top + rows]
        band[...] = cv2.addWeighted(band, 1.0, grain[:len(band)], strength, -32.0 * strength)
