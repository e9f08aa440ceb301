"""The road the finder found, drawn back onto the recorded frames: how its edges are checked by eye.

Each edge is a lateral position along the recorded path, seen from above (:mod:`tools.drivelog.road_view`); it is
drawn 3-15 m ahead, bent with the path's curvature and projected through the camera at the frame's ground
pitch, so an edge that sits on the painted line in the picture sits on it in the road finder's view too.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from models.data.labels import centred_average
from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera, ground_to_pixels
from tools.drivelog.path import RecordedDrive, curvature
from tools.drivelog.road import RoadEdges
from tools.sim.pictures.text import draw_text

#: Distances ahead (m) the edges are drawn over: from just past the bonnet to a little past the band the finder
#: measures (further on, a sharp bend leaves the parabola the edges are straightened along).
DRAWN_AHEAD_M = (3.0, 10.0)
#: The band the finder looks at (m ahead), shaded: where its edges were measured.
_EDGE, _BAND = (40, 220, 255), (255, 200, 60)  # BGR: yellow edges, light blue band


def draw_road(frame: np.ndarray, left_m: float, right_m: float, kappa: float, camera: UnityCamera = DEFAULT_CAMERA,
              scale: int = 2, band_m: tuple[float, float] = (4.0, 7.0)) -> np.ndarray:
    """``frame`` (RGB) as BGR, ``scale`` times larger, with the road's edges drawn on it."""
    img = cv2.resize(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR), None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
    z = np.linspace(*DRAWN_AHEAD_M, 60)
    lines = []
    for x in (left_m, right_m):
        u, v = ground_to_pixels(camera, x + 0.5 * kappa * z * z, z)
        lines.append(np.stack([u, v], axis=1) * scale)
    band = (z >= band_m[0]) & (z <= band_m[1])
    overlay = img.copy()
    cv2.fillPoly(overlay, [np.concatenate([lines[0][band], lines[1][band][::-1]]).astype(np.int32)], _BAND)
    img = cv2.addWeighted(overlay, 0.25, img, 0.75, 0)
    for line in lines:
        cv2.polylines(img, [line.astype(np.int32)], False, _EDGE, max(1, scale), cv2.LINE_AA)
    return img


def write_road_sheet(drive: RecordedDrive, road: RoadEdges, wheelbase_m: float, frames: Sequence[int], path: Path,
                     columns: int = 2, camera: UnityCamera = DEFAULT_CAMERA, scale: int = 2,
                     quality: int = 80) -> Path:
    """The chosen frames of ``drive`` with ``road`` drawn on them, in a grid, each labelled with its frame, the
    edges and the ground's pitch (JPEG or PNG by the suffix)."""
    kappa = curvature(centred_average(drive.steering, 9), wheelbase_m)  # as the road finder straightened them
    tiles = []
    for i in frames:
        pitch = camera.pitch_deg if road.pitch_deg is None else float(road.pitch_deg[i])
        tile = draw_road(read_jpeg_file(drive.frames[i]), float(road.left_m[i]), float(road.right_m[i]),
                         float(kappa[i]), replace(camera, pitch_deg=pitch), scale)
        draw_text(tile, f"#{i}  road {road.left_m[i]:+.1f} / {road.right_m[i]:+.1f} m  ground pitch {pitch:.1f} deg",
                  (4, 14), px=11, box=True)
        tiles.append(tile)
    blank = np.zeros_like(tiles[0])
    tiles += [blank] * (-len(tiles) % columns)
    sheet = np.vstack([np.hstack(tiles[r:r + columns]) for r in range(0, len(tiles), columns)])
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), sheet, [cv2.IMWRITE_JPEG_QUALITY, quality]):
        raise OSError(f"{path}: could not write the picture")
    return path
