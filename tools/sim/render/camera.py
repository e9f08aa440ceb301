"""Pinhole cameras on the car and the per-pixel tables that make rendering a handful of remaps.

A camera is fixed to the car, so where each pixel's ray meets the flat ground -- in the car's frame --
never changes. Those ground points, the mip level each row needs, the fog weight of each pixel and
each sky pixel's direction are computed once here; per frame the renderer only rotates and translates
them by the car's pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import overload

import numpy as np

from protocol import camera as real
from protocol.errors import BadValue
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH

VFOV_DEG = real.VFOV_DEG  # vertical field of view, as Unity's Camera.fieldOfView (both rigs)
# the classic rig, the first headless camera (the real simulator's is protocol.camera's)
CAMERA_HEIGHT = 1.6  # metres above the road
CAMERA_FORWARD = 0.6  # metres ahead of the body centre (roof, above the windscreen)
CAMERA_PITCH_DEG = -4.0  # slightly down
# metres to the left of the centre line of the car (both rigs)
CAMERA_OFFSETS = {"center": 0.0, "left": real.SIDE_OFFSET_M, "right": -real.SIDE_OFFSET_M}
FOG_START, FOG_RANGE = 30.0, 250.0  # metres: no haze nearer than FOG_START, e-folding distance beyond
MAX_GROUND_DIST = 3000.0  # rays that graze the horizon are clamped to this distance
MIP_BIAS = 0.3  # >0 picks sharper mip levels (a little aliasing rather than blur)
MAX_MIP = 6


def focal_px() -> float:
    return real.focal_px(FRAME_HEIGHT, VFOV_DEG)


@overload
def fog_weight(dist: np.ndarray, density: float = 1.0) -> np.ndarray: ...
@overload
def fog_weight(dist: float, density: float = 1.0) -> float: ...
def fog_weight(dist: np.ndarray | float, density: float = 1.0) -> np.ndarray | float:
    """Share of the haze colour at ``dist`` metres (``density``: the track's haze factor)."""
    if density == 1.0:
        return 1.0 - np.exp(-np.maximum(np.asarray(dist) - FOG_START, 0.0) / FOG_RANGE)
    return 1.0 - np.exp(-np.maximum(np.asarray(dist) - FOG_START, 0.0) * density / FOG_RANGE)


class CameraModel:
    """One camera's geometry and precomputed ray tables (car frame: x forward, y left, z up)."""

    def __init__(self, lateral: float = 0.0, height: float = CAMERA_HEIGHT, forward: float = CAMERA_FORWARD,
                 pitch_deg: float = CAMERA_PITCH_DEG) -> None:
        self.lateral, self.height, self.forward, self.pitch_deg = lateral, height, forward, pitch_deg
        self.f = focal_px()
        self.cx, self.cy = (FRAME_WIDTH - 1) / 2, (FRAME_HEIGHT - 1) / 2
        p = math.radians(pitch_deg)
        fwd = np.array([math.cos(p), 0.0, math.sin(p)])
        right = np.array([0.0, -1.0, 0.0])
        down = np.cross(fwd, right)
        self.axes = np.stack([right, down, fwd])  # rows: camera x (right), y (down), z (forward) in the car frame
        u, v = np.meshgrid(np.arange(FRAME_WIDTH, dtype=np.float64), np.arange(FRAME_HEIGHT, dtype=np.float64))
        rays = ((u - self.cx) / self.f)[..., None] * right + ((v - self.cy) / self.f)[..., None] * down + fwd
        # first row whose every ray points below the horizon (no roll, so rows are level)
        self.horizon_row = int(min(FRAME_HEIGHT, max(0, math.floor(self.cy + self.f * math.tan(p)) + 1)))

        # ground: car-frame hit points (float32 2-channel image for cv2.transform), distances, fog
        g_rays = rays[self.horizon_row:]
        t = np.minimum(height / np.maximum(-g_rays[..., 2], 1e-9),
                       MAX_GROUND_DIST / np.linalg.norm(g_rays[..., :2], axis=-1))
        ground = np.array([forward, lateral]) + t[..., None] * g_rays[..., :2]
        self.ground_xy = np.ascontiguousarray(ground, dtype=np.float32)
        self.ground_dist = t * np.linalg.norm(g_rays, axis=-1)
        self.fog_rows, self.fog, self.clear = self.fog_tables(1.0)

        # ground footprint of a pixel at the centre column, per row (picks the mip level)
        mid = FRAME_WIDTH // 2
        along = np.abs(np.gradient(ground[:, mid, 0])) if len(ground) > 1 else np.ones(len(ground))
        across = np.abs(ground[:, mid + 1, 1] - ground[:, mid, 1])
        self._footprint = np.sqrt(np.maximum(along * across, 1e-12))

        # sky: azimuth (degrees, counter-clockwise, relative to the car's heading) and elevation per pixel
        s_rays = rays[: self.horizon_row]
        self.sky_azimuth = np.degrees(np.arctan2(s_rays[..., 1], s_rays[..., 0])).astype(np.float32)
        self.sky_elevation = np.degrees(
            np.arctan2(s_rays[..., 2], np.linalg.norm(s_rays[..., :2], axis=-1))).astype(np.float32)

    def fog_tables(self, density: float) -> tuple[int, np.ndarray, np.ndarray]:
        """Rows touched by fog below the horizon and their fog and clear weights (float32)."""
        fog = fog_weight(self.ground_dist, density).astype(np.float32)
        rows = int(np.count_nonzero(fog.max(1) > 0.004))  # fog only touches rows near the horizon
        return rows, np.ascontiguousarray(fog[:rows]), np.ascontiguousarray(1.0 - fog[:rows])

    def mip_bands(self, texel_m: float) -> list[tuple[int, int, int]]:
        """(level, first row, end row) bands of ground rows, rows relative to the horizon row."""
        lvl = np.clip(np.floor(np.log2(self._footprint / texel_m) + MIP_BIAS), 0, MAX_MIP).astype(int)
        bands, start = [], 0
        for r in range(1, len(lvl) + 1):
            if r == len(lvl) or lvl[r] != lvl[start]:
                bands.append((int(lvl[start]), start, r))
                start = r
        return bands

    def project(self, cam_xyz: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) -> pixel coordinates (..., 2)."""
        z = np.maximum(cam_xyz[..., 2], 1e-3)
        return np.stack([self.cx + self.f * cam_xyz[..., 0] / z, self.cy + self.f * cam_xyz[..., 1] / z], -1)


@dataclass(frozen=True)
class CameraRig:
    """Where the three cameras sit on the car, and whether the car's bonnet is in view."""

    name: str
    height: float = CAMERA_HEIGHT
    pitch_deg: float = CAMERA_PITCH_DEG
    forward: float = CAMERA_FORWARD
    side_offset: float = CAMERA_OFFSETS["left"]
    bonnet: bool = False


#: The rigs a simulation can use. ``unity`` (the default): the real simulator's camera as measured on its
#: frames (:mod:`protocol.camera`: its pitch puts the horizon at row 64-65) with its bonnet
#: (``tools/sim/render/bonnet.py``). ``classic``: the first
#: headless camera (the paper's tables and the models trained before the unity rig; version-1 tracks
#: render with it byte for byte as they always did).
RIGS: dict[str, CameraRig] = {
    "classic": CameraRig("classic"),
    "unity": CameraRig("unity", height=real.HEIGHT_M, pitch_deg=-real.PITCH_DEG, side_offset=real.SIDE_OFFSET_M,
                       bonnet=True),  # pitch: + is up here
}
DEFAULT_RIG = "unity"
#: The rig of a model whose record names none: every model made before the unity rig learnt classic frames.
LEGACY_RIG = "classic"


def camera_rig(name: str) -> CameraRig:
    try:
        return RIGS[name]
    except KeyError:
        raise BadValue(f"unknown camera rig {name!r}; expected one of {', '.join(RIGS)}") from None


def camera_models(rig: str = DEFAULT_RIG) -> dict[str, CameraModel]:
    r = camera_rig(rig)
    sides = {"center": 0.0, "left": r.side_offset, "right": -r.side_offset}
    return {name: CameraModel(lateral=off, height=r.height, forward=r.forward, pitch_deg=r.pitch_deg)
            for name, off in sides.items()}


def jitter_rotation(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """Rotation of camera coordinates (x right, y down, z forward) for pitch (+ = nose up) and roll
    (+ = right side down, so the horizon tilts counter-clockwise in the image)."""
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(p), math.sin(p)], [0, -math.sin(p), math.cos(p)]])
    rz = np.array([[math.cos(r), math.sin(r), 0], [-math.sin(r), math.cos(r), 0], [0, 0, 1.0]])
    return rz @ rx


def jitter_homography(f: float, rotation: np.ndarray) -> np.ndarray:
    """Image warp K R K^-1 of a camera rotated by ``rotation`` (see :func:`jitter_rotation`).

    A pure rotation of a pinhole camera maps its image by this homography whatever the scene depth, so
    bumps (small pitch/roll jitter) are an exact per-frame warp rather than a re-render.
    """
    cx, cy = (FRAME_WIDTH - 1) / 2, (FRAME_HEIGHT - 1) / 2
    k = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])
    return k @ rotation @ np.linalg.inv(k)
