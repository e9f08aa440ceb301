"""A contact sheet of generated worlds: two camera frames and a map per world, to see the distribution.

Worlds are built one after the other and their caches dropped, so a sheet of many worlds needs the
memory of one.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from protocol.facts import FRAME_HEIGHT
from tools.sim.pictures.text import draw_text
from tools.sim.render.renderer import Renderer
from tools.sim.render.world import Pose, clear_caches, get_world
from tools.sim.track.files import parse_track
from tools.sim.track.road import Track
from tools.sim.worldgen.config import WorldGenConfig
from tools.sim.worldgen.generate import DEFAULT_CONFIG, generate_world

MAP_PX = FRAME_HEIGHT


def _pose(track: Track, s: float) -> Pose:
    lane = -track.road_width / 4 if track.lanes == 2 else 0.0
    x, y, h = track.point_at(s)
    return Pose(x - math.sin(h) * lane, y + math.cos(h) * lane, h)


def _map(track: Track, marks: list[float]) -> np.ndarray:
    """Top-down outline of the loop, start and the two frames' positions marked."""
    img = np.full((MAP_PX, MAP_PX, 3), 24, np.uint8)
    pts = track.centerline
    lo, hi = pts.min(0), pts.max(0)
    scale = (MAP_PX - 16) / max(float((hi - lo).max()), 1.0)
    px = np.stack([(pts[:, 0] - lo[0]) * scale + 8, MAP_PX - 8 - (pts[:, 1] - lo[1]) * scale], 1)
    kinds = track.surface_kinds()
    colours = [(200, 200, 200), (150, 100, 60), (190, 150, 100), (230, 230, 220), (170, 160, 140), (140, 140, 150)]
    for k in np.unique(kinds).tolist():
        seg = np.where(kinds == k, 1, 0)
        for a in np.nonzero(seg)[0][::2]:
            b = (a + 2) % len(px)
            cv2.line(img, tuple(np.round(px[a]).astype(int)), tuple(np.round(px[b]).astype(int)), colours[k], 2,
                     cv2.LINE_AA)
    for w in track.scenery.water:
        c = ((w.center[0] - lo[0]) * scale + 8, MAP_PX - 8 - (w.center[1] - lo[1]) * scale)
        cv2.ellipse(img, (int(c[0]), int(c[1])), (max(1, int(w.radius[0] * scale)), max(1, int(w.radius[1] * scale))),
                    -w.angle_deg, 0, 360, (60, 110, 170), 1, cv2.LINE_AA)
    for s, colour in zip(marks, ((80, 220, 80), (240, 200, 40)), strict=False):
        i = int(s / track.spacing) % len(px)
        cv2.circle(img, tuple(np.round(px[i]).astype(int)), 4, colour, -1, cv2.LINE_AA)
    return img


def world_tile(seed: int, config: WorldGenConfig = DEFAULT_CONFIG) -> np.ndarray:
    """Frame on the start straight, frame before the tightest curve, the map; a caption underneath."""
    doc = generate_world(seed, config)
    track = parse_track(doc, doc["name"])
    r = Renderer(get_world(track), seed=seed)
    tight = float(track.s[int(np.argmax(np.abs(track.curvature)))]) - 12.0
    a, b = (track.start_s + 10.0) % track.length, tight % track.length
    frames = [r.render(_pose(track, a)), r.render(_pose(track, b))]
    tile = np.concatenate(frames + [_map(track, [a, b])], 1)
    cap = np.zeros((34, tile.shape[1], 3), np.uint8)
    look = track.appearance
    draw_text(cap, f"{seed}  {track.length:.0f} m  {track.scenery.theme}  {track.lanes}x{track.road_width:.1f} m  "
                   f"min R {track.min_radius:.1f} m  sun {track.sun_elevation_deg:.0f} deg  "
                   f"clouds {track.sky.clouds:.2f}", (6, 14), px=12)
    draw_text(cap, f"surface {doc['surfaces'][0]['kind'] if doc['surfaces'] else 'asphalt'}, lines "
                   f"{track.edges.line_color}/{track.edges.line_style}, verge {track.edges.verge}, "
                   f"trees {track.scenery.trees.count}, EV {look.exposure_ev:+.2f}, blur {look.blur:.1f}, "
                   f"noise {look.noise:.1f}", (6, 29), px=12)
    clear_caches()
    return np.concatenate([tile, cap], 0)


def write_sheet(seeds: list[int], path: str | Path, columns: int = 2, config: WorldGenConfig = DEFAULT_CONFIG) -> Path:
    """A PNG grid of :func:`world_tile` for ``seeds``."""
    tiles = [world_tile(s, config) for s in seeds]
    blank = np.zeros_like(tiles[0])
    rows = [np.concatenate((tiles[i:i + columns] + [blank] * columns)[:columns], 1)
            for i in range(0, len(tiles), columns)]
    sheet = np.concatenate(rows, 0)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR)):
        raise OSError(f"{path}: could not write the contact sheet")
    return path
