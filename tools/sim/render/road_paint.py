"""The road painted onto the ground albedo: shoulders, surfaces, markings, kerbs and bridge decks.

Bands at signed offsets from the centre line are filled with OpenCV polygons (C++ speed,
anti-aliased, sub-texel precision). What version-1 tracks use is painted exactly as before; the
version-2 surfaces (concrete, gravel, worn asphalt) and edge styles (:class:`tools.sim.track.looks.Edges`)
are added around it.
"""

from __future__ import annotations

import cv2
import numpy as np

from tools.sim.track.road import SURFACE_KINDS, Track

SHIFT = 4  # sub-texel bits for cv2 drawing
LINE_W = 0.15  # painted line width, metres
LINE_INSET = 0.05  # gap between a line's outer edge and the nominal road edge
ASPHALT_EXTRA = 0.3  # asphalt beyond the edge line
DASH, GAP = 3.0, 6.0  # centre-line dash pattern, metres
KERB_RADIUS = 45.0  # curves tighter than this get kerbs on the inside (when the track asks for kerbs)
KERB_W, KERB_STRIPE = 0.6, 1.0
PLANK = 0.3  # bridge plank width along the road
DECK_EXTRA = 0.7  # bridge deck beyond the edge of the road (the rails stand on it)
EDGE_DASH, EDGE_GAP = 2.0, 3.0  # dashed edge lines, metres
JOINT_EVERY = 4.5  # concrete slab length, metres
PAVED = ("asphalt", "worn_asphalt", "concrete")  # surfaces that carry painted lines and kerbs


class Painter:
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
    out: list[tuple[float, float, str]] = []
    for a, b in zip(change, np.r_[change[1:], change[0] + n], strict=True):
        out.append((a * spacing, b * spacing, SURFACE_KINDS[int(kinds[a])]))
    return out


def curve_runs(mask: np.ndarray, spacing: float, pad: float) -> list[tuple[float, float]]:
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



def paint_road(track: Track, img: np.ndarray, x0: float, y1: float, res: float, pal: dict,
               rng: np.random.Generator) -> None:
    """Shoulders and surfaces run by run, then markings, kerbs and bridge planks."""
    p = Painter(track, img, x0, y1, res)
    half = track.road_width / 2
    edges = track.edges
    verge = pal["shoulder"] if edges.verge == "shoulder" else pal[f"verge_{edges.verge}"]
    runs = surface_runs(track.surface_kinds(), track.spacing, track.length)
    for s0, s1, kind in runs:
        if kind != "bridge":
            p.fill(p.band(s0, s1, -half - track.shoulder_width, half + track.shoulder_width), verge)
    line = pal["line"] if edges.line_color == "white" else pal["yellow"]
    centre = {"theme": pal["dash"], "white": pal["line"], "yellow": pal["yellow"]}[edges.center_color]
    for s0, s1, kind in runs:
        if kind in PAVED:
            base = pal["asphalt"] if kind == "asphalt" else pal["worn" if kind == "worn_asphalt" else "concrete"]
            p.fill(p.band(s0, s1, -half - ASPHALT_EXTRA, half + ASPHALT_EXTRA), base)
            if kind == "worn_asphalt":
                _paint_patches(p, s0, s1, half, pal, rng)
            elif kind == "concrete":
                joints = [np.r_[p.curve(np.array([c]), -half), p.curve(np.array([c]), half)]
                          for c in np.arange(s0, s1, JOINT_EVERY)]
                cv2.polylines(p.img, joints, False, pal["joint"], 1, cv2.LINE_AA, SHIFT)
            ink = line if kind != "worn_asphalt" else tuple((a + b) // 2 for a, b in zip(line, base, strict=True))
            if edges.line_style != "none":
                for sgn in (-1, 1):
                    d_out = sgn * (half - LINE_INSET)
                    d_in = sgn * (half - LINE_INSET - LINE_W)
                    lo, hi = min(d_in, d_out), max(d_in, d_out)
                    if edges.line_style == "solid":
                        p.fill(p.band(s0, s1, lo, hi), ink)
                    else:
                        p.fill(_dashes(p, s0, s1, lo, hi, EDGE_DASH, EDGE_GAP), ink)
            if track.lanes == 2 and edges.center_style != "none":
                if edges.center_style == "dashed":
                    p.fill(_dashes(p, s0, s1, -LINE_W / 2, LINE_W / 2, DASH, GAP), centre)
                else:
                    p.fill(p.band(s0, s1, -LINE_W / 2, LINE_W / 2), centre)
        elif kind in ("dirt", "gravel"):
            p.fill(p.band(s0, s1, -half - ASPHALT_EXTRA, half + ASPHALT_EXTRA), pal[kind])
            rut, w = (pal["rut"], 0.25) if kind == "dirt" else (pal["gravel2"], 0.35)
            for d in (-0.75 * half, -0.25 * half, 0.25 * half, 0.75 * half):  # tyre ruts
                p.fill(p.band(s0, s1, d - w, d + w), rut)
        elif kind == "bridge":
            _paint_bridge(p, s0, s1, half, pal)
    if track.scenery.kerbs:
        _paint_kerbs(p, track, runs, half, pal)


def _dashes(p: Painter, s0: float, s1: float, lo: float, hi: float, dash: float, gap: float) -> list[np.ndarray]:
    out = []
    for a in np.arange(s0, s1 - dash, dash + gap):
        out += p.band(a, a + dash, lo, hi)
    return out


def _paint_patches(p: Painter, s0: float, s1: float, half: float, pal: dict, rng: np.random.Generator) -> None:
    """Repair patches of darker asphalt on worn road: a few random rectangles per 20 m."""
    polys = []
    for c in rng.uniform(s0, s1, max(1, int((s1 - s0) / 20))):
        d = rng.uniform(-half + 0.5, half - 0.5)
        w, length = rng.uniform(0.4, 1.6), rng.uniform(1.0, 5.0)
        polys += p.band(c, c + length, d - w / 2, d + w / 2)
    p.fill(polys, pal["patch"])


def _paint_bridge(p: Painter, s0: float, s1: float, half: float, pal: dict) -> None:
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


def _paint_kerbs(p: Painter, track: Track, runs: list, half: float, pal: dict) -> None:
    """Red and white kerb stripes outside the edge line on the inside of sharp paved curves."""
    asphalt = np.zeros(len(track.s), bool)
    for s0, s1, kind in runs:
        if kind in PAVED:
            idx = np.arange(int(round(s0 / track.spacing)), int(round(s1 / track.spacing))) % len(track.s)
            asphalt[idx] = True
    for sgn in (1, -1):  # inside of left turns is the left side
        sharp = (sgn * track.curvature > 1.0 / KERB_RADIUS) & asphalt
        for a, b in curve_runs(sharp, track.spacing, pad=4.0):
            lo, hi = sorted((sgn * (half - LINE_INSET), sgn * (half + KERB_W)))
            stripes: list[list[np.ndarray]] = [[], []]
            for k, c in enumerate(np.arange(a, b, KERB_STRIPE)):
                stripes[k % 2] += p.band(c, c + KERB_STRIPE, lo, hi)
            p.fill(stripes[0], pal["kerb_red"])
            p.fill(stripes[1], pal["kerb_white"])
