"""The headless renderer: 320x160 RGB frames of a :class:`~tools.sim.render.world.World` from the car's cameras.

Per frame: the sky is one remap of the panorama, the ground is an affine transform of precomputed
car-frame ground points followed by one ``cv2.remap`` per mip band, distant rows are blended into the
haze, props are painted far to near, and light intensity rescales each pixel's direct-light share
(kept in the frame's alpha channel) before the alpha is dropped. Bumps are an exact homography warp.
"""

from __future__ import annotations

import math
from functools import lru_cache
from weakref import WeakKeyDictionary

import cv2
import numpy as np

from protocol.errors import BadValue
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH
from tools.sim.render.bonnet import ROWS as BONNET_ROWS
from tools.sim.render.bonnet import bonnet_layer, draw_bonnet
from tools.sim.render.camera import (
    CAMERA_OFFSETS,
    DEFAULT_RIG,
    CameraModel,
    camera_models,
    camera_rig,
    jitter_homography,
    jitter_rotation,
)
from tools.sim.render.postfx import PostFx
from tools.sim.render.sky import EL_BOTTOM, EL_TOP, PANO_H, PANO_W, SKY_DIRECT_SHARE
from tools.sim.render.sprites import PropPainter
from tools.sim.render.world import Pose, World

__all__ = ["CAMERA_OFFSETS", "Pose", "Renderer"]

SKY_PAD = PANO_W // 4  # panorama columns repeated on each side (a camera sees at most 1/4 turn to either side)


class _CameraState:
    """A camera model plus the per-world tables (mip bands, sky row map, haze block) it renders with."""

    def __init__(self, model: CameraModel, world: World) -> None:
        self.model = model
        g = world.ground
        self.bands = [(lvl, model.horizon_row + a, model.horizon_row + b, model.ground_xy[a:b])
                      for lvl, a, b in model.mip_bands(g.res)]
        self.sky_x = np.ascontiguousarray(model.sky_azimuth * np.float32(PANO_W / 360.0))
        rows = (EL_TOP - model.sky_elevation) / (EL_TOP - EL_BOTTOM) * (PANO_H - 1)
        self.sky_y = np.ascontiguousarray(rows, dtype=np.float32)
        self.fog_rows, self.fog, self.clear = model.fog_rows, model.fog, model.clear
        if world.track.appearance.haze != 1.0:
            self.fog_rows, self.fog, self.clear = model.fog_tables(world.track.appearance.haze)
        haze = np.array(world.haze + (round(255 * SKY_DIRECT_SHARE),), np.uint8)
        self.haze_block = np.ascontiguousarray(np.broadcast_to(haze, (self.fog_rows, FRAME_WIDTH, 4)))


#: per world, per rig: its cameras' tables and its sky with margins, while the world lives (nothing in them refers
#: to the world, which would keep it alive)
_WORLD_TABLES: WeakKeyDictionary[World, dict[str, tuple[dict[str, _CameraState], np.ndarray]]] = WeakKeyDictionary()
_camera_models = lru_cache(maxsize=4)(camera_models)  # the rigs' camera geometry, made once
_bonnet_layer = lru_cache(maxsize=16)(bonnet_layer)  # per lateral offset


class Renderer:
    """Renders frames of one world. Not thread-safe (it reuses a scratch frame); make one per thread.

    ``seed`` seeds the per-frame appearance jitter of version-2 tracks (frames are deterministic for a
    seed and the order of the calls).
    """

    def __init__(self, world: World, seed: int = 0, rig: str = DEFAULT_RIG) -> None:
        self.world = world
        self.rig = camera_rig(rig)
        self.postfx = PostFx(world.track.appearance, seed)
        # the tables of the world and rig (read only), shared by its renderers: an episode's is made in no time
        shared = _WORLD_TABLES.setdefault(world, {})
        if rig not in shared:
            # the panorama with wrapped margins: cv2.remap's BORDER_WRAP path is ~3x slower than a plain lookup
            pano = world.panorama
            sky = np.ascontiguousarray(np.concatenate([pano[:, -SKY_PAD:], pano, pano[:, :SKY_PAD]], 1))
            shared[rig] = ({}, sky)  # each camera's tables made for its first frame
        self._states, self._sky = shared[rig]
        self._models = _camera_models(rig)
        self.props = PropPainter(world)
        self._fb = np.empty((FRAME_HEIGHT, FRAME_WIDTH, 4), np.uint8)
        self._lut_cache: dict[float, tuple[np.ndarray, float]] = {}

    def render(self, pose: Pose, camera: str = "center", light_intensity: float = 1.0,
               pitch_deg: float = 0.0, roll_deg: float = 0.0, rows: tuple[int, int] | None = None) -> np.ndarray:
        """One RGB frame (160, 320, 3) uint8 from ``camera`` ("center", "left" or "right") of a car at ``pose``.

        ``light_intensity`` scales the direct sunlight (1 = the world's default; ambient light stays),
        ``pitch_deg``/``roll_deg`` tilt the camera for this frame (bumps; + = nose up / right side down).
        ``rows=(top, bottom)``: only the rows ``top:bottom`` are wanted; they are the full frame's bytes, the others
        are left unspecified (the sky and ground are drawn for those rows alone: a tilted camera's warp reads the
        whole frame, so with bumps the whole frame is drawn).
        """
        cam = self._state(camera)
        m = cam.model
        fb: np.ndarray = self._fb
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        hr = m.horizon_row
        top, bottom = self._drawn_rows(rows, pitch_deg or roll_deg)

        # sky: panorama column from the absolute azimuth of each pixel
        if top < hr:
            shift = np.float32((math.degrees(pose.yaw) % 360.0) * PANO_W / 360.0 + SKY_PAD)
            end = min(hr, bottom)
            cv2.remap(self._sky, cam.sky_x[top:end] + shift, cam.sky_y[top:end], cv2.INTER_LINEAR,
                      dst=fb[top:end], borderMode=cv2.BORDER_REPLICATE)

        # ground: car-frame points -> texel coordinates of each mip level -> bilinear lookups
        g = self.world.ground
        inv = 1.0 / g.res
        tx = pose.x - g.x0  # the camera offset is already inside ground_xy
        ty = g.y1 - pose.y
        for lvl, a, b, pts in cam.bands:
            if a < top or b > bottom:  # the band's rows outside the wanted ones are left out
                if b <= top or a >= bottom:
                    continue
                pts = pts[max(a, top) - a:min(b, bottom) - a]
                a, b = max(a, top), min(b, bottom)
            k = inv / (1 << lvl)
            half = 0.5 - 0.5 / (1 << lvl)  # pyrDown texel centres sit between their parents
            mat = np.array([[c * k, -s * k, tx * k - half], [-s * k, -c * k, ty * k - half]], np.float32)
            maps = cv2.transform(pts, mat)
            cv2.remap(g.mips[lvl], maps, None, cv2.INTER_LINEAR, dst=fb[a:b], borderMode=cv2.BORDER_CONSTANT,
                      borderValue=g.border)
        first, end = max(hr, top), min(hr + cam.fog_rows, bottom)
        if first < end:
            lo, hi = first - hr, end - hr
            hazed = fb[first:end]
            hazed[:] = cv2.blendLinear(hazed, cam.haze_block[lo:hi], cam.clear[lo:hi], cam.fog[lo:hi])

        axes = m.axes @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # camera axes, world coordinates
        if pitch_deg or roll_deg:  # a rotated camera sees the same image through a homography
            rot = jitter_rotation(pitch_deg, roll_deg)
            fb = cv2.warpPerspective(fb, jitter_homography(m.f, rot), (FRAME_WIDTH, FRAME_HEIGHT),
                                     flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            axes = rot @ axes
        out = cv2.cvtColor(fb, cv2.COLOR_RGBA2RGB)
        if light_intensity != 1.0:
            lut, scale = self._gain_lut(light_intensity)
            gain = cv2.cvtColor(cv2.LUT(fb[..., 3], lut), cv2.COLOR_GRAY2RGB)
            out = cv2.multiply(out, gain, scale=scale)

        # props, lit for the intensity and seen by the (jittered) camera, straight onto the RGB frame
        pos = np.array([pose.x + c * m.forward - s * m.lateral, pose.y + s * m.forward + c * m.lateral, m.height])
        self.props.draw(out, m, pos, axes, light_intensity)
        # the bonnet, fixed to the car: drawn after the bumps' warp, before the camera's processing (where wanted)
        if self.rig.bonnet and bottom > BONNET_ROWS.start:
            draw_bonnet(out, _bonnet_layer(m.lateral), light_intensity)
        return self.postfx.apply(out) if self.postfx.active else out

    def _drawn_rows(self, rows: tuple[int, int] | None, tilted: float) -> tuple[int, int]:
        """The rows whose sky and ground are drawn for the wanted ``rows``: all of them for a tilted camera (its warp
        reads the whole frame), a few more on each side where the camera's processing blurs."""
        if rows is None or tilted:
            return 0, FRAME_HEIGHT
        top, bottom = rows
        if not 0 <= top < bottom <= FRAME_HEIGHT:
            raise ValueError(f"rows must be 0 <= top < bottom <= {FRAME_HEIGHT}, got {rows}")
        margin = self.postfx.margin if self.postfx.active else 0
        return max(0, top - margin), min(FRAME_HEIGHT, bottom + margin)

    def render_all(self, pose: Pose, light_intensity: float = 1.0, pitch_deg: float = 0.0,
                   roll_deg: float = 0.0) -> dict[str, np.ndarray]:
        """Frames of all three cameras, keyed by camera name."""
        return {name: self.render(pose, name, light_intensity, pitch_deg, roll_deg) for name in self._models}

    @property
    def cameras(self) -> dict[str, _CameraState]:
        """Every camera's tables (made here where no frame of that camera has been rendered yet)."""
        for name in self._models:
            self._state(name)
        return self._states

    def _state(self, camera: str) -> _CameraState:
        state = self._states.get(camera)
        if state is None:
            if camera not in self._models:
                raise ValueError(f"unknown camera {camera!r}; expected one of {sorted(self._models)}")
            state = self._states[camera] = _CameraState(self._models[camera], self.world)
        return state

    def _gain_lut(self, intensity: float) -> tuple[np.ndarray, float]:
        """uint8 table and scale of the brightness factor per direct-light share (alpha 0..255).

        factor = 1 + (intensity - 1) * share: the ambient part stays, the direct part scales. Fixed point
        keeps the multiply in uint8 (3x faster than float); the scale adapts so large factors still fit.
        """
        hit = self._lut_cache.get(intensity)
        if hit is None:
            if not math.isfinite(intensity) or intensity < 0:
                raise BadValue(f"light intensity must be a finite number >= 0, got {intensity!r}")
            factor = 1.0 + (intensity - 1.0) * np.arange(256) / 255.0
            one = 128 if factor.max() < 1.99 else 255.0 / factor.max()
            hit = (np.round(factor * one).astype(np.uint8), 1.0 / one)
            if len(self._lut_cache) > 64:
                self._lut_cache.clear()
            self._lut_cache[intensity] = hit
        return hit
