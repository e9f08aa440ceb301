"""Top-down ground albedo of a track: grass or forest floor, water, shoulders, road surfaces and markings.

The renderer draws the ground by inverse perspective mapping of this one texture (5 cm per texel by
default), so everything flat -- lines, kerbs, bridge planks, ponds -- is painted here once per track,
with OpenCV polygon fills (C++ speed, anti-aliased) rather than per-texel NumPy work. Lighting is
not applied here: :mod:`tools.sim.world` multiplies this albedo by a light map per sun direction.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from tools.sim.track import SURFACE_KINDS, Track

log = logging.getLogger(__name__)

TEXEL_M = 0.05  # preferred ground texture resolution, metres per texel
MAX_TEXELS = 48_000_000  # bigger tracks get coarser texels rather than an unbounded texture
MAX_SIDE = 30_000  # texels; cv2.remap addresses sources with 16-bit coordinates
MARGIN_M = 25.0  # ground painted beyond the outermost road edge; further out is a flat mean colour
SHIFT = 4  # sub-texel bits for cv2 drawing
LINE_W = 0.15  # painted line width, metres
LINE_INSET = 0.05  # gap between a line's outer edge and the nominal road edge
ASPHALT_EXTRA = 0.3  # asphalt beyond the edge line
DASH, GAP = 3.0, 6.0  # centre-line dash pattern, metres
KERB_RADIUS = 45.0  # curves tighter than this get kerbs on the inside (when the track asks for kerbs)
KERB_W, KERB_STRIPE = 0.6, 1.0
PLANK = 0.3  # bridge plank width along the road
DECK_EXTRA = 0.7  # bridge deck beyond the edge of the road (the rails stand on it)

# RGB albedo palettes (values before lighting; lighting at the default sun keeps them near these)
PALETTES: dict[str, dict[str, tuple[int, int, int]]] = {
    "meadow": {"ground": (78, 128, 52), "ground2": (112, 138, 60), "shoulder": (132, 112, 84),
               "asphalt": (92, 92, 96), "line": (232, 232, 226), "dash": (232, 200, 60),
               "shore": (150, 138, 100), "water": (48, 86, 112), "deck": (138, 100, 66), "deck2": (118, 84, 54),
               "gap": (58, 42, 30), "beam": (96, 74, 56), "dirt": (150, 122, 88), "rut": (118, 96, 70),
               "kerb_red": (196, 44, 38), "kerb_white": (230, 230, 226)},
    "forest": {"ground": (58, 82, 40), "ground2": (96, 84, 52), "shoulder": (118, 108, 92),
               "asphalt": (84, 84, 88), "line": (228, 228, 222), "dash": (228, 228, 222),
               "shore": (110, 100, 76), "water": (40, 70, 84), "deck": (130, 96, 64), "deck2": (110, 80, 52),
               "gap": (50, 38, 28), "beam": (90, 70, 52), "dirt": (138, 112, 80), "rut": (108, 88, 64),
               "kerb_red": (196, 44, 38), "kerb_white": (230, 230, 226)},
}


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


class _Painter:
    """Draws bands at signed offsets from the centre line onto the albedo with sub-texel precision."""

    def __init__(self, track: Track, img: np.ndarray, x0: float, y1: float, res: float) -> None:
        self.t, self.img, self.x0, self.y1, self.res = track, img, x0, y1, res

    def curve(self, s: np.ndarray, d: float | np.ndarray) -> np.ndarray:
        """Points at arc lengths ``s`` and lateral offsets ``d`` (+ = left), as fixed-point texels."""
        t = self.t
        u = (np.asarray(s, dtype=np.float64) % t.length) / t.spacing
        i = np.floor(u).astype(np.int64) % len(t.s)
        j = (i + 1) % len(t.s)
        f = (u - np.floor(u))[:, None]
        p = t.centerline[i] * (1 - f) + t.centerline[j] * f
        n = t.normals[i] * (1 - f) + t.normals[j] * f
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        q = p + n * np.asarray(d, dtype=np.float64).reshape(-1, 1)
        uv = np.stack([(q[:, 0] - self.x0) / self.res, (self.y1 - q[:, 1]) / self.res], 1)
        return np.round(uv * (1 << SHIFT)).astype(np.int32)

    def band(self, s0: float, s1: float, d_lo: float, d_hi: float) -> list[np.ndarray]:
        """Polygon(s) covering arc lengths [s0, s1] between offsets d_lo and d_hi.

        One polygon per band (a whole-loop band is an outer and an inner contour, which cv2.fillPoly's
        even-odd rule turns into a ring): overlapping pieces in one fillPoly call would cancel out.
        """
        step = self.t.spacing
        if s1 - s0 >= self.t.length - 1e-6:
            s = np.arange(len(self.t.s)) * step
            return [self.curve(s, d_lo), self.curve(s, d_hi)]
        s = np.unique(np.r_[np.arange(s0, s1, step), s1])
        return [np.r_[self.curve(s, d_lo), self.curve(s[::-1], d_hi)]]

    def fill(self, polys: list[np.ndarray], color: tuple[int, int, int]) -> None:
        if polys:
            cv2.fillPoly(self.img, polys, color, cv2.LINE_AA, SHIFT)


def surface_runs(kinds: np.ndarray, spacing: float, length: float) -> list[tuple[float, float, str]]:
    """Contiguous (s0, s1, kind) runs of surface kinds around the loop; s1 may exceed the length."""
    n = len(kinds)
    change = np.nonzero(kinds != np.roll(kinds, 1))[0]
    if len(change) == 0:
        return [(0.0, length, SURFACE_KINDS[int(kinds[0])])]
    out = []
    for a, b in zip(change, np.r_[change[1:], change[0] + n], strict=True):
        out.append((a * spacing, b * spacing, SURFACE_KINDS[int(kinds[a])]))
    return out


def _curve_runs(mask: np.ndarray, spacing: float, pad: float) -> list[tuple[float, float]]:
    """(s0, s1) intervals where ``mask`` holds around the loop, padded by ``pad`` metres each side."""
    n = len(mask)
    if mask.all():
        return [(0.0, n * spacing)]
    if not mask.any():
        return []
    start = int(np.argmin(mask))  # begin the scan on a False sample so no run is split
    m = np.roll(mask, -start)
    edges = np.diff(np.r_[0, m.astype(np.int8), 0])
    a_idx, b_idx = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
    return [((a + start) * spacing - pad, (b + start) * spacing + pad) for a, b in zip(a_idx, b_idx, strict=True)]


def paint_ground(track: Track, seed: int = 0) -> GroundAlbedo:
    """Paint the albedo texture of ``track`` (deterministic for a track and seed)."""
    rng = np.random.default_rng(seed)
    pal = PALETTES[track.scenery.theme]
    reach = track.road_width / 2 + track.shoulder_width + MARGIN_M
    lo = track.centerline.min(0) - reach
    hi = track.centerline.max(0) + reach
    area = float(np.prod(hi - lo))
    res = max(TEXEL_M, math.sqrt(area / MAX_TEXELS), float((hi - lo).max()) / MAX_SIDE)
    if res > TEXEL_M:
        log.warning("track %s spans %.0f x %.0f m: ground texture coarsened to %.1f cm per texel",
                    track.name, *(hi - lo), res * 100)
    w = int(math.ceil((hi[0] - lo[0]) / res / 8)) * 8
    h = int(math.ceil((hi[1] - lo[1]) / res / 8)) * 8
    x0, y1 = float(lo[0]), float(hi[1])

    # 1. large-scale ground colour at 8x coarser resolution, faded to the mean colour towards the border
    ch, cw = h // 8, w // 8
    n1, n2 = fbm((ch, cw), rng), fbm((ch, cw), rng, cells=(6, 24, 90))
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

    # 3. road: shoulders and surfaces run by run, then markings, kerbs and bridge planks
    p = _Painter(track, img, x0, y1, res)
    half = track.road_width / 2
    runs = surface_runs(track.surface_kinds(), track.spacing, track.length)
    for s0, s1, kind in runs:
        if kind != "bridge":
            p.fill(p.band(s0, s1, -half - track.shoulder_width, half + track.shoulder_width), pal["shoulder"])
    for s0, s1, kind in runs:
        if kind == "asphalt":
            p.fill(p.band(s0, s1, -half - ASPHALT_EXTRA, half + ASPHALT_EXTRA), pal["asphalt"])
            for sgn in (-1, 1):
                d_out = sgn * (half - LINE_INSET)
                d_in = sgn * (half - LINE_INSET - LINE_W)
                p.fill(p.band(s0, s1, min(d_in, d_out), max(d_in, d_out)), pal["line"])
            if track.lanes == 2:
                dashes = []
                for a in np.arange(s0, s1 - DASH, DASH + GAP):
                    dashes += p.band(a, a + DASH, -LINE_W / 2, LINE_W / 2)
                p.fill(dashes, pal["dash"])
        elif kind == "dirt":
            p.fill(p.band(s0, s1, -half - ASPHALT_EXTRA, half + ASPHALT_EXTRA), pal["dirt"])
            for d in (-0.75 * half, -0.25 * half, 0.25 * half, 0.75 * half):  # tyre ruts
                p.fill(p.band(s0, s1, d - 0.25, d + 0.25), pal["rut"])
        elif kind == "bridge":
            _paint_bridge(p, s0, s1, half, pal)
    if track.scenery.kerbs:
        _paint_kerbs(p, track, runs, half, pal)

    # 4. fine grain everywhere (a tiled noise patch; the large-scale colour hides the 25 m period)
    tile = (rng.standard_normal((512, 512, 1)) * 7 + rng.standard_normal((512, 512, 3)) * 3
            + cv2.resize(rng.standard_normal((128, 128)).astype(np.float32), (512, 512))[..., None] * 5)
    tile = np.clip(tile + 32, 0, 64).astype(np.uint8)
    grain = cv2.repeat(tile, h // 512 + 1, w // 512 + 1)[:h, :w]
    img = cv2.addWeighted(img, 1.0, grain, 1.0, -32.0)
    mean_rgb = tuple(int(v) for v in np.clip(mean, 0, 255))
    return GroundAlbedo(rgb=img, x0=x0, y1=y1, res=res, mean_rgb=mean_rgb, water=water)


def _paint_bridge(p: _Painter, s0: float, s1: float, half: float, pal: dict) -> None:
    """Wooden deck: planks across the road in two shades with dark gaps, and edge beams; no lines."""
    deck = half + DECK_EXTRA
    n = max(1, int((s1 - s0) / PLANK))
    bounds = np.linspace(s0, s1, n + 1)
    for shade in (0, 1):
        polys = [poly for k in range(shade, n, 2) for poly in p.band(bounds[k], bounds[k + 1], -deck, deck)]
        p.fill(polys, pal["deck"] if shade == 0 else pal["deck2"])
    gaps = [np.r_[p.curve(np.array([b]), -deck), p.curve(np.array([b]), deck)] for b in bounds]
    cv2.polylines(p.img, gaps, False, pal["gap"], 1, cv2.LINE_AA, SHIFT)
    for sgn in (-1, 1):
        lo, hi = sorted((sgn * (half + 0.2), sgn * deck))
        p.fill(p.band(s0, s1, lo, hi), pal["beam"])


def _paint_kerbs(p: _Painter, track: Track, runs: list, half: float, pal: dict) -> None:
    """Red and white kerb stripes outside the edge line on the inside of sharp asphalt curves."""
    asphalt = np.zeros(len(track.s), bool)
    for s0, s1, kind in runs:
        if kind == "asphalt":
            idx = np.arange(int(round(s0 / track.spacing)), int(round(s1 / track.spacing))) % len(track.s)
            asphalt[idx] = True
    for sgn in (1, -1):  # inside of left turns is the left side
        sharp = (sgn * track.curvature > 1.0 / KERB_RADIUS) & asphalt
        for a, b in _curve_runs(sharp, track.spacing, pad=4.0):
            lo, hi = sorted((sgn * (half - LINE_INSET), sgn * (half + KERB_W)))
            stripes = [[], []]
            for k, c in enumerate(np.arange(a, b, KERB_STRIPE)):
                stripes[k % 2] += p.band(c, c + KERB_STRIPE, lo, hi)
            p.fill(stripes[0], pal["kerb_red"])
            p.fill(stripes[1], pal["kerb_white"])
