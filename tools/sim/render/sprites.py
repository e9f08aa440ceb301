"""Drawing the vertical props (trees, poles, cones, bridge rails) as depth-sorted flat polygons.

Props are screen-aligned billboards. Everything that does not depend on the camera -- each prop's
vertex template (sideways offset and height of every corner) and its lit colours -- is tabulated once
per world, so a frame costs one NumPy projection of all visible props plus a few OpenCV polygon calls
per prop, painted far to near. A coarse grid keeps the candidates to the props within sight.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from protocol.facts import FRAME_WIDTH
from tools.sim.render.camera import CameraModel, fog_weight
from tools.sim.render.scenery import (
    BARRIER_HEIGHT,
    CONIFER,
    RAIL_HEIGHT,
    TCROWN_R,
    TCROWN_Z,
    TH,
    TKIND,
    TTINT,
    TTRUNK_R,
)
from tools.sim.render.sky import SKY_DIRECT_SHARE
from tools.sim.render.world import World
from tools.sim.track.cones import CONE_HEIGHT, CONE_RADIUS
from tools.sim.track.themes import BOULDER_COLOURS, TREES

VIEW_DISTANCE = {theme: t.view_distance for theme, t in TREES.items()}  # metres; further: haze and panorama
LOD_DIST = 35.0  # beyond this, trees are drawn with fewer shapes
NEAR = 0.8  # metres; props closer to the camera plane than this are skipped
CELL = 16.0  # metres, side of the visibility grid cells
SHIFT = 3  # sub-pixel bits for cv2 drawing
LAMBERT_LIT, LAMBERT_MID, LAMBERT_DARK = 0.75, 0.45, 0.12  # direct light on a prop's sunny/middle/far side

# albedos (RGB)
TRUNK = (92, 68, 48)
POLE = (150, 152, 156)
CONE_ORANGE, CONE_WHITE, CONE_FOOT = (240, 96, 22), (238, 238, 238), (44, 44, 44)
RAIL = (112, 88, 64)
BARRIER = (170, 172, 176)  # galvanised steel
RAIL_CULL_MARGIN = 10.0  # metres: a rail whose every point is this far beyond the view distance is skipped

# prop kinds and their drawing recipes: (shape, first vertex, end vertex, colour slot)
BROADLEAF_K, CONIFER_K, POLE_K, CONE_K = 0, 1, 2, 3
POLY, FIR, CROWN, HIGHLIGHT = 0, 1, 2, 3  # convex polygon, non-convex polygon, circles
K_VERTS, N_COLOURS = 18, 4
RECIPES: dict[tuple[int, bool, bool], list[tuple[int, int, int, int]]] = {}
for _right in (False, True):  # key: (kind, near, sun lights the right side); colour slots are per kind
    _l, _r = (1, 2) if _right else (2, 1)  # tree slots: 0 bark, 1 shaded, 2 sunlit, 3 average
    RECIPES[(CONIFER_K, True, _right)] = [(POLY, 0, 4, 0), (FIR, 10, 15, _l), (FIR, 5, 10, _r)]
    RECIPES[(CONIFER_K, False, _right)] = [(POLY, 15, 18, 3)]
    RECIPES[(BROADLEAF_K, True, _right)] = [(POLY, 0, 4, 0), (CROWN, 4, 5, 1), (HIGHLIGHT, 4, 5, 2)]
    RECIPES[(BROADLEAF_K, False, _right)] = [(POLY, 0, 4, 0), (CROWN, 4, 5, 1)]
    RECIPES[(POLE_K, True, _right)] = RECIPES[(POLE_K, False, _right)] = [(POLY, 0, 4, 0), (POLY, 4, 8, 0)]
    RECIPES[(CONE_K, True, _right)] = RECIPES[(CONE_K, False, _right)] = [
        (POLY, 0, 4, 0), (POLY, 4, 8, 1), (POLY, 8, 12, 2)]

RECIPE_LIST = [RECIPES[(k, n, r)] for k in range(4) for n in (False, True) for r in (False, True)]


class PropPainter:
    """Draws one world's props into RGBA frames; shared by all cameras of a renderer."""

    def __init__(self, world: World) -> None:
        self.world = world
        self.haze = np.array(world.haze + (round(255 * SKY_DIRECT_SHARE),), np.float64)
        self.sun_vector = world.sun.vector
        self.view_dist = VIEW_DISTANCE[world.track.scenery.theme]
        self.fog_density = world.track.appearance.haze
        self._tabulate(world)
        # (polyline, height, lit colour RGBA, bounding centre, radius): bridge rails, then guard rails
        rail_lit, barrier_lit = (self._lit(np.array([albedo], np.float64), np.ones(1), 0.6)[0]
                                 for albedo in (RAIL, BARRIER))
        self.rails = [(r, RAIL_HEIGHT, rail_lit) + _bounds(r) for r in world.props.rails]
        self.rails += [(r, BARRIER_HEIGHT, barrier_lit) + _bounds(r) for r in world.props.barriers]
        self._cells: dict[tuple[int, int], np.ndarray] = {}

    # -- tables ---------------------------------------------------------------------------------------

    def _tabulate(self, world: World) -> None:
        """Per prop: position, kind, cull size, vertex template (sideways a, height z), colours, crown radius."""
        p = world.props
        vis = world.sun_visibility
        xy, kind, size, ta, tz, col, crown = [], [], [], [], [], [], []
        t = p.trees
        if len(t):
            n = len(t)
            z0 = np.zeros(n)
            tr, h, cr, cz = t[:, TTRUNK_R], t[:, TH], t[:, TCROWN_R], t[:, TCROWN_Z]
            zt = cz + 0.4 * cr
            z1 = cz + 0.45 * (h - cz)
            zl = z1 + 0.25 * (h - z1)
            # vertices: 0-3 trunk, 4 crown centre; a two-tier fir as two non-convex halves: 5-9 right
            # (axis foot, lower corner, waist, upper corner, apex), 10-14 left (mirrored, reversed);
            # 15-17 a single far-away triangle (left, right, apex)
            waist = cr * (zl - z1) / np.maximum(zl - cz, 1e-6)
            a = np.column_stack([-tr, tr, 0.7 * tr, -0.7 * tr, z0,
                                 z0, cr, waist, 0.62 * cr, z0,
                                 -cr, z0, z0, -0.62 * cr, -waist,
                                 -cr, cr, z0])
            z = np.column_stack([z0, z0, zt, zt, h - cr, cz, cz, z1, z1, h, cz, cz, h, z1, z1, cz, cz, h])
            leaf = _leaf_colours(t, TREES[world.track.scenery.theme].leaves)
            cols = np.stack([self._lit(np.broadcast_to(TRUNK, (n, 3)), vis["trees"], LAMBERT_MID),
                             self._lit(leaf, vis["trees"], LAMBERT_DARK), self._lit(leaf, vis["trees"], LAMBERT_LIT),
                             self._lit(leaf, vis["trees"], LAMBERT_MID)], 1)
            xy.append(t[:, :2])
            kind.append(np.where(t[:, TKIND] == CONIFER, CONIFER_K, BROADLEAF_K))
            size.append(cr)
            ta.append(a)
            tz.append(z)
            col.append(cols)
            crown.append(cr)
        if len(p.poles):
            n = len(p.poles)
            h = p.poles[:, 2]
            a = np.tile([-0.09, 0.09, 0.06, -0.06, -0.05, 1.4, 1.4, -0.05] + [0.0] * (K_VERTS - 8), (n, 1))
            z = np.column_stack([np.zeros((n, 2)), h, h, h - 0.12, h - 0.02, h + 0.06, h - 0.02,
                                 np.zeros((n, K_VERTS - 8))])
            c = self._lit(np.broadcast_to(POLE, (n, 3)), vis["poles"], 0.5)
            xy.append(p.poles[:, :2])
            kind.append(np.full(n, POLE_K))
            size.append(np.full(n, 1.5))
            ta.append(a)
            tz.append(z)
            col.append(np.repeat(c[:, None], N_COLOURS, 1))
            crown.append(np.zeros(n))
        if len(p.cones):
            n = len(p.cones)
            r, hc = CONE_RADIUS, CONE_HEIGHT
            a = np.tile([-1.3 * r, 1.3 * r, 1.3 * r, -1.3 * r, -r, r, 0.08, -0.08,
                         -0.62 * r, 0.62 * r, 0.42 * r, -0.42 * r] + [0.0] * (K_VERTS - 12), (n, 1))
            z = np.tile([0.0, 0.0, 0.05, 0.05, 0.05, 0.05, hc, hc,
                         0.42 * hc, 0.42 * hc, 0.62 * hc, 0.62 * hc] + [0.0] * (K_VERTS - 12), (n, 1))
            v = vis["cones"]
            cols = np.stack([self._lit(np.broadcast_to(c, (n, 3)), v, 0.7)
                             for c in (CONE_FOOT, CONE_ORANGE, CONE_WHITE, CONE_WHITE)], 1)
            xy.append(p.cones)
            kind.append(np.full(n, CONE_K))
            size.append(np.full(n, 0.4))
            ta.append(a)
            tz.append(z)
            col.append(cols)
            crown.append(np.zeros(n))
        if xy:
            self.xy = np.concatenate(xy)
            self.kind = np.concatenate(kind).astype(np.int64)
            self.size = np.concatenate(size)
            self.ta, self.tz = np.concatenate(ta), np.concatenate(tz)
            self.colours = np.concatenate(col)
            self.crown = np.concatenate(crown)
        else:
            self.xy = np.zeros((0, 2))

    def _lit(self, albedo: np.ndarray, vis: np.ndarray, lambert: float) -> np.ndarray:
        """RGBA (n, 4): albedo lit by ambient + direct light; alpha = direct-light share (for intensity)."""
        w = self.world
        direct = w.direct * lambert * np.asarray(vis, np.float64)
        light = w.ambient + direct
        return np.column_stack([np.minimum(albedo * light[:, None], 255), 255 * direct / light])

    def _candidates(self, x: float, y: float) -> np.ndarray:
        key = (int(math.floor(x / CELL)), int(math.floor(y / CELL)))
        hit = self._cells.get(key)
        if hit is None:
            c = (np.array(key) + 0.5) * CELL
            hit = np.nonzero(np.hypot(self.xy[:, 0] - c[0], self.xy[:, 1] - c[1]) < self.view_dist + CELL)[0]
            self._cells[key] = hit
        return hit

    # -- drawing -------------------------------------------------------------------------------------

    def draw(self, img: np.ndarray, cam: CameraModel, pos: np.ndarray, axes: np.ndarray,
             intensity: float = 1.0) -> None:
        """Paint props into the RGB ``img`` for a camera at world ``pos`` with world axes ``axes`` (3x3 rows).

        Colours are lit for ``intensity`` here (the frame's own pixels were rescaled before), so props
        go straight onto the final 3-channel image.
        """
        haze = self.haze[:3] * (1 + (intensity - 1) * self.haze[3] / 255)
        if self.rails:
            self._draw_rails(img, cam, pos, axes, intensity, haze)
        idx = self._candidates(pos[0], pos[1])
        if len(idx) == 0:
            return
        rel = self.xy[idx] - pos[:2]
        cam_xyz = rel @ axes[:, :2].T - pos[2] * axes[:, 2]
        z = cam_xyz[:, 2]
        half_fov = (FRAME_WIDTH / 2) / cam.f
        ok = (z > NEAR) & (z < self.view_dist) & (np.abs(cam_xyz[:, 0]) < z * half_fov + self.size[idx])
        if not ok.any():
            return
        sel = idx[ok]
        base = cam_xyz[ok]
        z = base[:, 2]
        up = axes[:, 2]  # world up in camera coordinates
        pts = base[:, None, :] + self.tz[sel][..., None] * up
        pts[..., 0] += self.ta[sel]
        front = pts[..., 2].min(1) > 0.3  # a tall prop right beside the camera pokes behind it: skip it
        if not front.all():
            sel, base, pts = sel[front], base[front], pts[front]
            z = base[:, 2]
        zc = pts[..., 2]
        scale = cam.f * (1 << SHIFT)
        px = np.empty(pts.shape[:-1] + (2,), np.int32)
        px[..., 0] = np.round(cam.cx * (1 << SHIFT) + scale * pts[..., 0] / zc)
        px[..., 1] = np.round(cam.cy * (1 << SHIFT) + scale * pts[..., 1] / zc)
        fog = fog_weight(np.sqrt((base * base).sum(1)), self.fog_density)[:, None, None]
        rgba = self.colours[sel]
        rgb = rgba[..., :3] if intensity == 1.0 else rgba[..., :3] * (1 + (intensity - 1) / 255 * rgba[..., 3:])
        cols = (rgb * (1 - fog) + haze * fog).tolist()
        # crowns: centre vertex 4, radius from the distance; highlight nudged towards the sun
        sun_cam = axes @ self.sun_vector
        sun2 = sun_cam[:2] / max(math.hypot(sun_cam[0], sun_cam[1]), 1e-6)
        rad = scale * self.crown[sel] / z
        centres, radii = px[:, 4].tolist(), rad.tolist()
        sun_x, sun_y = sun2.tolist()
        lit_right = sun_x > 0
        recipe = (self.kind[sel] * 4 + (z < LOD_DIST) * 2 + int(lit_right)).tolist()
        min_hi = 3 << SHIFT
        for i in np.argsort(-z, kind="stable").tolist():
            p, c = px[i], cols[i]
            for shape, a, b, slot in RECIPE_LIST[recipe[i]]:
                if shape == POLY:
                    cv2.fillConvexPoly(img, p[a:b], c[slot], cv2.LINE_AA, SHIFT)
                elif shape == FIR:
                    cv2.fillPoly(img, [p[a:b]], c[slot], cv2.LINE_AA, SHIFT)
                elif shape == CROWN:
                    cv2.circle(img, tuple(centres[i]), int(radii[i]), c[slot], -1, cv2.LINE_AA, SHIFT)
                elif int(radii[i]) > min_hi:  # the highlight, nudged towards the sun (as NumPy rounds: half to even)
                    (x, y), nudge = centres[i], 0.3 * radii[i]
                    cv2.circle(img, (round(x + sun_x * nudge), round(y + sun_y * nudge)), int(int(radii[i]) * 0.68),
                               c[slot], -1, cv2.LINE_AA, SHIFT)

    def _draw_rails(self, fb: np.ndarray, cam: CameraModel, pos: np.ndarray, axes: np.ndarray, intensity: float,
                    haze: np.ndarray) -> None:
        """Bridge and guard rails: a top and a middle rail and posts, clipped at the camera plane.

        The three heights of a rail are projected in one call (the same arithmetic point by point as one
        call per height: the same pixels, with fewer NumPy calls per frame)."""
        up = axes[:, 2]
        reach = self.view_dist + RAIL_CULL_MARGIN
        for rail, top, lit, centre, radius in self.rails:
            if math.hypot(pos[0] - centre[0], pos[1] - centre[1]) > radius + reach:
                continue
            cam_xyz = (rail - pos[:2]) @ axes[:, :2].T - pos[2] * up
            front = cam_xyz[:, 2] > NEAR
            count = np.count_nonzero(front)
            if count < 2:
                continue
            d, mid = np.sort(np.hypot(cam_xyz[front, 0], cam_xyz[front, 2])), count // 2  # np.median without its checks
            dist = float(d[mid]) if count % 2 else float((d[mid - 1] + d[mid]) / 2)
            if dist > self.view_dist:
                continue
            fog = float(fog_weight(dist, self.fog_density))
            rgb = lit[:3] * (1 + (intensity - 1) / 255 * lit[3])
            color = (rgb * (1 - fog) + haze * fog).tolist()
            heights = np.stack([cam_xyz + top * up, cam_xyz + 0.5 * top * up, cam_xyz])
            px = np.round(cam.project(heights) * (1 << SHIFT)).astype(np.int32)  # top rail, middle rail, feet
            runs = _runs(front)
            for level, width in ((0, 2), (1, 1)):
                for run in runs:
                    cv2.polylines(fb, [px[level, run]], False, color, width, cv2.LINE_AA, SHIFT)
            cv2.polylines(fb, list(np.stack([px[2, front], px[0, front]], 1)), False, color, 1, cv2.LINE_AA, SHIFT)


def _bounds(rail: np.ndarray) -> tuple[np.ndarray, float]:
    centre = rail.mean(0)
    return centre, float(np.linalg.norm(rail - centre, axis=1).max())


def _leaf_colours(t: np.ndarray, leaves: dict[int, tuple]) -> np.ndarray:
    """Crown albedo per tree: its kind's colour brightened or darkened by its tint (version 1), or a
    blend of the kind's two colours by the tint; boulders are grey blends."""
    kinds = t[:, TKIND].astype(np.int64)
    tint = t[:, TTINT]
    out = np.empty((len(t), 3))
    for k in np.unique(kinds).tolist():
        m = kinds == k
        cols = BOULDER_COLOURS if k == 2 else leaves[k]
        if len(cols) == 1:
            out[m] = np.array([cols[0]], np.float64) * (1 + 0.12 * tint[m])[:, None]
        else:
            u = ((tint[m] + 1) / 2)[:, None]
            out[m] = (1 - u) * np.array(cols[0], np.float64) + u * np.array(cols[1], np.float64)
    return out


def _runs(mask: np.ndarray) -> list[slice]:
    """Slices of at least two consecutive True values of a 1-D mask."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return [slice(a, b) for a, b in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0], strict=True)
            if b - a >= 2]
