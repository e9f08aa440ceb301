"""Sky panorama: a 360 degree strip of sky, clouds, sun glow and distant hills or mountains.

Everything above the horizon is far enough away to be drawn from one cylindrical image indexed by
azimuth and elevation, so the sky costs one small remap per frame however the car turns.
"""

from __future__ import annotations

import math

import numpy as np

from tools.sim.render.scenery import Sun
from tools.sim.render.texture import fbm
from tools.sim.track.looks import SkySpec
from tools.sim.track.themes import SKIES

PANO_W = 2048  # columns over 360 degrees of azimuth (counter-clockwise from east)
EL_TOP, EL_BOTTOM = 36.0, -4.0  # degrees covered by the rows
PANO_H = 200
HAZE: dict[str, tuple[int, int, int]] = {theme: sky.haze for theme, sky in SKIES.items()}
SKY_DIRECT_SHARE = 0.3  # share of the sky's brightness that follows the light intensity


def elevation_to_row(el_deg: np.ndarray | float) -> np.ndarray | float:
    return (EL_TOP - np.asarray(el_deg)) / (EL_TOP - EL_BOTTOM) * (PANO_H - 1)


def haze_colour(theme: str, sky: SkySpec) -> tuple[int, int, int]:
    """Horizon and fog colour: the track's own or its theme's."""
    return sky.haze if sky.haze is not None else SKIES[theme].haze


def make_panorama(theme: str, sun: Sun, sky: SkySpec | None = None) -> np.ndarray:
    """RGBA panorama (PANO_H, PANO_W, 4); alpha holds the sky's direct-light share for light intensity."""
    sky = sky or SkySpec()
    rng = np.random.default_rng(sky.seed)
    el = np.linspace(EL_TOP, EL_BOTTOM, PANO_H, dtype=np.float32)[:, None]
    az = np.linspace(0, 360, PANO_W, endpoint=False, dtype=np.float32)[None, :]
    haze = np.array(haze_colour(theme, sky), np.float32)
    zenith = np.array(sky.zenith if sky.zenith is not None else SKIES[theme].zenith, np.float32)
    t = np.clip(el / EL_TOP, 0, 1) ** 0.55
    img = (1 - t)[..., None] * haze + t[..., None] * zenith
    img = np.broadcast_to(img, (PANO_H, PANO_W, 3)).copy()

    # warm glow and a disc around the sun
    d_az = np.radians((az - sun.azimuth_deg + 180) % 360 - 180)
    cos_ang = (np.cos(np.radians(el)) * math.cos(math.radians(sun.elevation_deg)) * np.cos(d_az)
               + np.sin(np.radians(el)) * math.sin(math.radians(sun.elevation_deg)))
    ang = np.degrees(np.arccos(np.clip(cos_ang, -1, 1)))
    glow = 0.35 * np.exp(-ang / 18.0) + 0.6 * np.exp(-((ang / 2.2) ** 2))
    img += glow[..., None] * (np.array((255, 246, 220), np.float32) - img)

    # clouds: thresholded noise, flattened towards the horizon, brighter on top
    n = fbm((PANO_H, PANO_W), rng, cells=(8, 24, 64, 160), amps=(1.0, 0.5, 0.3, 0.15))
    n = np.concatenate([n[:, : PANO_W // 2], n[:, : PANO_W // 2][:, ::-1]], 1)  # periodic in azimuth
    cover = np.clip((n - sky.cloud_threshold) * 2.5, 0, 1) * np.clip((el - 3) / 8, 0, 1) ** 0.5
    shade = 1 - 0.18 * np.clip((n - 0.3) * 2, 0, 1)
    img = (1 - cover[..., None]) * img + cover[..., None] * (np.array((246, 248, 250), np.float32) * shade[..., None])

    # distant terrain: layered silhouettes (heights in degrees), aerial perspective towards the haze
    layers = [(_ridge(rng, r.base, r.amp, r.harmonics, r.jag), r.color, r.fade) for r in SKIES[theme].ridges]
    for height, color, fade in layers:
        mask = el[:, 0][:, None] <= height[None, :]
        c = np.array(color, np.float32) * (1 - fade) + haze * fade
        img[mask] = c
    below = el[:, 0] < 0
    img[below] = haze
    # bottom of the terrain dissolves into the haze where the far ground meets the horizon
    h = np.clip(1 - (el[:, 0] - 0.0) / 1.2, 0, 1)[:, None, None]
    img = img * (1 - h * 0.6) + haze * (h * 0.6)

    rgba = np.empty((PANO_H, PANO_W, 4), np.uint8)
    rgba[..., :3] = np.clip(img, 0, 255).astype(np.uint8)
    rgba[..., 3] = int(round(255 * SKY_DIRECT_SHARE))
    return rgba


def _ridge(rng: np.random.Generator, base: float, amp: float, harmonics: tuple[int, ...], jag: float = 0.0):
    x = np.linspace(0, 2 * np.pi, PANO_W, endpoint=False)
    prof = np.zeros(PANO_W)
    for k in harmonics:
        prof += rng.uniform(0.4, 1.0) / math.sqrt(k) * np.sin(k * x + rng.uniform(0, 2 * np.pi))
    prof = base + amp * (prof - prof.min()) / max(np.ptp(prof), 1e-6)
    if jag:  # tree tops: small periodic spikes of random height
        prof += jag * np.abs(np.sin(x * PANO_W / 7)) * rng.uniform(0.5, 1.0, PANO_W)
    return prof.astype(np.float32)

