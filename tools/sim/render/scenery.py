"""Vertical props of a track -- trees, lamp poles, bridge rails, traffic cones -- and their ground shadows.

Props are placed once per track (seeded, so every run sees the same forest) and kept as plain float
arrays the renderer can cull and project in bulk. Shadows are rasterised onto a top-down mask by
projecting each prop along the sun direction onto the flat ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from tools.sim.render.road_paint import DECK_EXTRA, SHIFT, curve_runs, surface_runs
from tools.sim.render.texture import GroundAlbedo
from tools.sim.track.cones import CONE_HEIGHT, CONE_RADIUS
from tools.sim.track.road import SURFACE_KINDS, Track
from tools.sim.track.themes import TREES

BROADLEAF, CONIFER, BOULDER = 0, 1, 2  # boulders (version-2 themes) are drawn like broadleaf crowns
RAIL_HEIGHT = 1.0  # metres, top rail of the bridge
RAIL_POST_SPACING = 2.0
BARRIER_HEIGHT = 0.75  # metres, guard rails outside sharp curves (edges.barriers)
BARRIER_RADIUS = 60.0  # curves tighter than this get a guard rail on the outside
TREE_MIN_GAP = 1.8  # metres between trunks
# shadow opacity (0..255) per part: foliage lets some light through, solid parts do not
OPACITY_SOLID, OPACITY_BROADLEAF, OPACITY_CONIFER = 255, 225, 235

# tree table columns
TX, TY, TH, TCROWN_R, TCROWN_Z, TTRUNK_R, TKIND, TTINT = range(8)


@dataclass(frozen=True, eq=False)
class Props:
    """Everything that stands on the ground. Arrays are float64 tables, one row per prop."""

    trees: np.ndarray  # (n, 8): x, y, height, crown radius, crown base height, trunk radius, kind, tint
    poles: np.ndarray  # (n, 3): x, y, height
    cones: np.ndarray  # (n, 2): x, y
    rails: tuple[np.ndarray, ...]  # polylines (m, 2) of bridge rails, RAIL_HEIGHT high, posts every 2 m
    barriers: tuple[np.ndarray, ...] = ()  # polylines (m, 2) of guard rails, BARRIER_HEIGHT high


@dataclass(frozen=True)
class Sun:
    """Direction to the sun: azimuth counter-clockwise from east (x axis), elevation above the horizon."""

    azimuth_deg: float
    elevation_deg: float

    @property
    def horizontal(self) -> np.ndarray:
        a = math.radians(self.azimuth_deg)
        return np.array([math.cos(a), math.sin(a)])

    @property
    def vector(self) -> np.ndarray:
        e = math.radians(self.elevation_deg)
        return np.r_[math.cos(e) * self.horizontal, math.sin(e)]

    @property
    def shadow_offset(self) -> np.ndarray:
        """Ground displacement of a shadow per metre of height (points away from the sun)."""
        return -self.horizontal / math.tan(math.radians(max(self.elevation_deg, 1.0)))


def place_props(track: Track, ground: GroundAlbedo, cones: np.ndarray | None = None) -> Props:
    """Place trees, poles and bridge rails for ``track`` (deterministic per track file)."""
    rails = _bridge_rails(track)
    poles = _poles(track, ground)
    trees = _trees(track, ground, poles)
    cone_xy = np.zeros((0, 2)) if cones is None else np.asarray(cones, dtype=np.float64).reshape(-1, 2)
    return Props(trees=trees, poles=poles, cones=cone_xy, rails=rails, barriers=_barriers(track))


def _distance_to_line(track: Track, xy: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest centre-line sample (1 m grid is plenty for placement)."""
    line = track.centerline[:: max(1, int(1.0 / track.spacing))]
    out = np.empty(len(xy))
    for lo in range(0, len(xy), 1024):
        d = np.linalg.norm(xy[lo:lo + 1024, None] - line[None], axis=2)
        out[lo:lo + 1024] = d.min(1)
    return out


def _trees(track: Track, ground: GroundAlbedo, poles: np.ndarray) -> np.ndarray:
    spec = track.scenery.trees
    if spec.count == 0:
        return np.zeros((0, 8))
    rng = np.random.default_rng(spec.seed)
    k = spec.count * 4
    s = rng.uniform(0, track.length, k)
    side = rng.choice([-1.0, 1.0], k)
    offset = spec.min_offset + (spec.max_offset - spec.min_offset) * rng.uniform(0, 1, k) ** 1.6
    idx = (s / track.spacing).astype(np.int64) % len(track.s)
    xy = track.centerline[idx] + track.normals[idx] * (side * offset)[:, None] + rng.normal(0, 1.0, (k, 2))
    ok = (_distance_to_line(track, xy) >= spec.min_offset) & ~ground.is_water(xy)
    if len(poles):
        ok &= np.linalg.norm(xy[:, None] - poles[None, :, :2], axis=2).min(1) > 2.0
    xy = xy[ok]
    keep: list[int] = []
    for i in range(len(xy)):  # greedy thinning so trunks never intersect
        if len(keep) >= spec.count:
            break
        if not keep or np.min(np.hypot(*(xy[keep] - xy[i]).T)) >= TREE_MIN_GAP:
            keep.append(i)
    xy = xy[keep]
    n = len(xy)
    theme = TREES[track.scenery.theme]
    kind = (rng.uniform(0, 1, n) < theme.conifer_share).astype(np.float64)
    h = rng.uniform(spec.min_height, spec.max_height, n)
    crown_r = np.where(kind == CONIFER, rng.uniform(0.18, 0.24, n) * h, rng.uniform(0.26, 0.34, n) * h)
    crown_z = np.where(kind == CONIFER, rng.uniform(0.12, 0.25, n) * h, h - 1.8 * crown_r)
    trunk_r = 0.12 + 0.018 * h
    tint = rng.uniform(-1, 1, n)
    if theme.boulder_share:  # a sphere resting on the ground, no trunk to speak of
        rock = (kind == BROADLEAF) & (rng.uniform(0, 1, n) < theme.boulder_share)
        h = np.where(rock, h * 0.3, h)
        kind[rock] = BOULDER
        crown_r = np.where(rock, 0.5 * h, crown_r)
        crown_z = np.where(rock, 0.1 * h, crown_z)
        trunk_r = np.where(rock, 0.01, trunk_r)
    return np.column_stack([xy, h, crown_r, crown_z, trunk_r, kind, tint])


def _poles(track: Track, ground: GroundAlbedo) -> np.ndarray:
    spec = track.scenery.poles
    if spec.spacing <= 0:
        return np.zeros((0, 3))
    s = np.arange(0.0, track.length, spec.spacing)
    idx = (s / track.spacing).astype(np.int64)
    xy = track.centerline[idx] + track.normals[idx] * spec.offset
    on_road = np.array([track.surface_at(v) == "bridge" for v in s])
    ok = (_distance_to_line(track, xy) >= abs(spec.offset) - 0.5) & ~ground.is_water(xy) & ~on_road
    xy = xy[ok]
    return np.column_stack([xy, np.full(len(xy), spec.height)])


def _bridge_rails(track: Track) -> tuple[np.ndarray, ...]:
    rails = []
    d = track.road_width / 2 + DECK_EXTRA - 0.2
    for s0, s1, kind in surface_runs(track.surface_kinds(), track.spacing, track.length):
        if kind != "bridge":
            continue
        s = np.arange(s0, s1 + 1e-6, RAIL_POST_SPACING)
        idx = np.round(s / track.spacing).astype(np.int64) % len(track.s)
        for sgn in (-1.0, 1.0):
            rails.append(track.centerline[idx] + track.normals[idx] * sgn * d)
    return tuple(rails)


def _barriers(track: Track) -> tuple[np.ndarray, ...]:
    """Guard rails on the outside of curves tighter than BARRIER_RADIUS, off bridges (they have rails)."""
    if not track.edges.barriers:
        return ()
    paved = track.surface_kinds() != SURFACE_KINDS.index("bridge")
    d = track.road_width / 2 + track.shoulder_width + 0.4
    out = []
    for sgn in (1.0, -1.0):  # the outside of a left turn is the right side
        sharp = (sgn * track.curvature > 1.0 / BARRIER_RADIUS) & paved
        for a, b in curve_runs(sharp, track.spacing, pad=8.0):
            s = np.arange(a, b + 1e-6, RAIL_POST_SPACING)
            idx = np.round(s / track.spacing).astype(np.int64) % len(track.s)
            out.append(track.centerline[idx] - track.normals[idx] * sgn * d)
    return tuple(out)


# ---------------------------------------------------------------------------------------------- shadows


def draw_shadows(props: Props, sun: Sun, shape: tuple[int, int], x0: float, y1: float, res: float) -> np.ndarray:
    """Top-down shadow mask (uint8, 255 = no direct sunlight) of all props, unblurred."""
    mask = np.zeros(shape, np.uint8)
    off = sun.shadow_offset
    perp = np.array([-sun.horizontal[1], sun.horizontal[0]])
    scale = 1 << SHIFT

    def px(xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64)
        return np.round(np.stack([(xy[..., 0] - x0) / res, (y1 - xy[..., 1]) / res], -1) * scale).astype(np.int32)

    def column(xy: np.ndarray, r: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Shadow quads (n, 4, 2) of vertical cylinders of radius r from the ground to height z."""
        a, b = xy + perp * r[:, None], xy - perp * r[:, None]
        return px(np.stack([a, b, b + off * z[:, None], a + off * z[:, None]], 1))

    t = props.trees
    if len(t):
        xy = t[:, [TX, TY]]
        for q in column(xy, t[:, TTRUNK_R], t[:, TCROWN_Z] + 0.5):
            cv2.fillConvexPoly(mask, q, OPACITY_SOLID, cv2.LINE_AA, SHIFT)
        ring = np.stack([np.cos(np.linspace(0, 2 * np.pi, 14, endpoint=False)),
                         np.sin(np.linspace(0, 2 * np.pi, 14, endpoint=False))], 1)
        sin_el = math.sin(math.radians(max(sun.elevation_deg, 1.0)))
        along = -sun.horizontal
        for row, p in zip(t, xy, strict=True):
            r = row[TCROWN_R]
            if row[TKIND] == CONIFER:
                base = p + off * row[TCROWN_Z] + ring * r
                pts = np.r_[base, [p + off * row[TH]]]
                hull = cv2.convexHull(px(pts))
                cv2.fillConvexPoly(mask, hull, OPACITY_CONIFER, cv2.LINE_AA, SHIFT)
            else:  # sphere -> ellipse stretched along the shadow direction
                c = p + off * (row[TH] - r)
                pts = c + np.outer(ring[:, 0] * r / sin_el, along) + np.outer(ring[:, 1] * r, perp)
                cv2.fillConvexPoly(mask, px(pts), OPACITY_BROADLEAF, cv2.LINE_AA, SHIFT)
    if len(props.poles):
        p = props.poles
        for q in column(p[:, :2], np.full(len(p), 0.1), p[:, 2]):
            cv2.fillConvexPoly(mask, q, OPACITY_SOLID, cv2.LINE_AA, SHIFT)
    if len(props.cones):
        c = props.cones
        tri = np.stack([c + perp * CONE_RADIUS, c - perp * CONE_RADIUS, c + off * CONE_HEIGHT], 1)
        for q in px(tri):
            cv2.fillConvexPoly(mask, q, OPACITY_SOLID, cv2.LINE_AA, SHIFT)
    rails = [(rail, RAIL_HEIGHT) for rail in props.rails] + [(b, BARRIER_HEIGHT) for b in props.barriers]
    for rail, top in rails:
        width = max(1, int(round(0.08 / res)))
        for z in (top, top / 2):
            cv2.polylines(mask, [px(rail + off * z)], False, OPACITY_SOLID, width, cv2.LINE_AA, SHIFT)
        posts = [px(np.stack([p, p + off * top])) for p in rail]
        cv2.polylines(mask, posts, False, OPACITY_SOLID, width, cv2.LINE_AA, SHIFT)
    return mask
