"""A renderable world: a track's lit ground texture (with mip levels), props, sun and sky.

Building a world is split by what each part depends on, and each part is cached on exactly that:

* ground albedo and prop placement depend on the track only (``Track.digest``);
* shadows, the lit texture and its mips also depend on the sun (``light_direction_deg``) and cones;
* light *intensity* depends on nothing here: every texel carries, in its alpha channel, the share of
  its brightness that comes from direct sunlight, so the renderer rescales that share per frame.

Light model (Unity-like): ``colour = albedo * (AMBIENT + intensity * direct(sun) * sun_visibility)``,
with ``direct`` following Lambert's law for the flat ground.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import math
import mmap
import sys
import time
from collections import OrderedDict
from dataclasses import dataclass, replace

import cv2
import numpy as np

from tools.sim.render.scenery import TKIND, TX, TY, Props, Sun, draw_shadows, place_props
from tools.sim.render.sky import haze_colour, make_panorama
from tools.sim.render.texture import GroundAlbedo, paint_ground
from tools.sim.track.road import Track

log = logging.getLogger(__name__)

AMBIENT = 0.42  # light from the sky, unaffected by light intensity and present in shadows
DIRECT_AT_45 = 0.6  # direct sunlight on flat ground with the sun 45 degrees high, intensity 1
MIN_SUN_ELEVATION = 2.0  # degrees; the sun is clamped here rather than set below the horizon
SHADOW_DOWNSCALE = 2  # the shadow map has 2x coarser texels than the albedo (shadows are soft anyway)
SHADOW_BLUR = 1.2  # penumbra, in shadow-map texels
MIP_LEVELS = 7  # level L has texels 2**L times the base size
LIGHT_BAND_ROWS = 256  # the full-size texture is lit this many rows at a time (light_ground)
ALBEDO_CACHE, PROPS_CACHE, WORLD_CACHE = 2, 4, 3  # LRU sizes (a lake world holds ~0.35 GB)


@dataclass(frozen=True)
class Pose:
    """Vehicle body centre and heading: x east, y north (metres), yaw counter-clockwise from east (rad)."""

    x: float
    y: float
    yaw: float


def sun_for(track: Track, light_direction_deg: float = 0.0) -> Sun:
    """The track's sun rotated about the light's local X axis by ``light_direction_deg``.

    As in Unity, that axis is horizontal and perpendicular to the light's azimuth, so the rotation
    raises (+) or lowers (-) the sun in its vertical plane; past the zenith it continues on the other side.
    """
    el = track.sun_elevation_deg + light_direction_deg
    az = track.sun_azimuth_deg
    if el > 90.0:
        el, az = 180.0 - el, az + 180.0
    return Sun(azimuth_deg=az % 360.0, elevation_deg=max(el, MIN_SUN_ELEVATION))


def direct_light(sun: Sun) -> float:
    """Direct sunlight on the flat ground at intensity 1 (Lambert: proportional to sin(elevation))."""
    return DIRECT_AT_45 * math.sin(math.radians(sun.elevation_deg)) / math.sin(math.radians(45.0))


@dataclass(frozen=True, eq=False)
class LitGround:
    """Lit RGBA ground texture pyramid; alpha = share of the texel's brightness that is direct sunlight."""

    mips: tuple[np.ndarray, ...]
    x0: float
    y1: float
    res: float
    border: tuple[int, int, int, int]  # RGBA of the ground beyond the texture


class World:
    """Everything the renderer needs for one (track, light direction, cones) combination.

    Use :func:`get_world` to share worlds (and their ~0.3 GB of textures) between renderers.
    """

    def __init__(self, track: Track, light_direction_deg: float = 0.0, cones: np.ndarray | None = None,
                 keep_albedo: bool = True) -> None:
        """``keep_albedo=False``: the track's ground albedo leaves the cache and its memory goes back to the system
        band by band as it is lit (the same bytes; the peak is the lit texture's, not both at once), for a world
        that is the only one its process builds on the track (the albedo is painted again for another)."""
        t0 = time.perf_counter()
        self.track = track
        self.light_direction_deg = float(light_direction_deg)
        self.sun = sun_for(track, self.light_direction_deg)
        self.ambient = AMBIENT
        self.direct = direct_light(self.sun)
        albedo = _albedo(track)
        base = _base_props(track)
        self.props: Props = replace(base, cones=_cone_array(cones))
        self.haze = haze_colour(track.scenery.theme, track.sky)
        self.panorama = make_panorama(track.scenery.theme, self.sun, track.sky)  # its temporaries before the texture
        shadow = _shadow_map(albedo, self.props, self.sun)
        self.sun_visibility = _prop_visibility(self.props, shadow, albedo, self.sun)
        if not keep_albedo:
            forget_albedo(track)
        self.ground = light_ground(albedo, shadow, self.ambient, self.direct, consume=not keep_albedo)
        del albedo, shadow
        if not keep_albedo:
            trim_heap()  # the shadow map: what the process holds is the lit texture
        self.build_seconds = time.perf_counter() - t0
        log.debug("world %s light %+.1f deg, %d cones: built in %.2f s", track.name, self.light_direction_deg,
                  len(self.props.cones), self.build_seconds)

    @property
    def key(self) -> tuple:
        return world_key(self.track, self.light_direction_deg, self.props.cones)

    @property
    def direct_share(self) -> float:
        """Share of a sunlit surface's brightness that is direct light (scaled by light intensity)."""
        return self.direct / (self.ambient + self.direct)


# ---------------------------------------------------------------------------------------------- caching

_albedo_cache: OrderedDict[str, GroundAlbedo] = OrderedDict()
_props_cache: OrderedDict[str, Props] = OrderedDict()
_world_cache: OrderedDict[tuple, World] = OrderedDict()


def _lru(cache: OrderedDict, key, size: int, make):
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    value = make()
    cache[key] = value
    while len(cache) > size:
        cache.popitem(last=False)
    return value


def _albedo(track: Track) -> GroundAlbedo:
    return _lru(_albedo_cache, track.digest, ALBEDO_CACHE, lambda: paint_ground(track))


def _base_props(track: Track) -> Props:
    return _lru(_props_cache, track.digest, PROPS_CACHE, lambda: place_props(track, _albedo(track)))


def _cone_array(cones: np.ndarray | None) -> np.ndarray:
    return np.zeros((0, 2)) if cones is None else np.ascontiguousarray(cones, dtype=np.float64).reshape(-1, 2)


def world_key(track: Track, light_direction_deg: float = 0.0, cones: np.ndarray | None = None) -> tuple:
    cone_hash = hashlib.sha1(_cone_array(cones).tobytes()).hexdigest()[:16]
    return track.digest, round(float(light_direction_deg), 6), cone_hash


def get_world(track: Track, light_direction_deg: float = 0.0, cones: np.ndarray | None = None,
              keep_albedo: bool = True) -> World:
    """The cached :class:`World` for these inputs, built on first use (the last few are kept; ``keep_albedo``: as
    :class:`World` takes it, for a build)."""
    key = world_key(track, light_direction_deg, cones)
    return _lru(_world_cache, key, WORLD_CACHE, lambda: World(track, light_direction_deg, cones, keep_albedo))


def forget_albedo(track: Track) -> bool:
    """Drop ``track``'s ground albedo from the cache (128 MB for the lake; False: it held none): the worlds built
    keep their lit textures; building the track for another sun or cones paints it again (a second or less)."""
    return _albedo_cache.pop(track.digest, None) is not None


def clear_caches() -> None:
    """Drop every cached albedo, prop set and world (frees their memory)."""
    _albedo_cache.clear()
    _props_cache.clear()
    _world_cache.clear()


# ---------------------------------------------------------------------------------------------- lighting


def _shadow_map(albedo: GroundAlbedo, props: Props, sun: Sun) -> np.ndarray:
    """Blurred shadow opacity (uint8, 255 = no direct sun) at SHADOW_DOWNSCALE x coarser texels."""
    h, w = albedo.shape
    res = albedo.res * SHADOW_DOWNSCALE
    mask = draw_shadows(props, sun, (h // SHADOW_DOWNSCALE, w // SHADOW_DOWNSCALE), albedo.x0, albedo.y1, res)
    return cv2.GaussianBlur(mask, (0, 0), SHADOW_BLUR)


def light_ground(albedo: GroundAlbedo, shadow: np.ndarray, ambient: float, direct: float,
                 consume: bool = False) -> LitGround:
    """Multiply the albedo by the light map and stack the direct-light share as alpha; build mips.

    The full-size texture is made LIGHT_BAND_ROWS rows at a time, each band from the shadow rows it reads: the
    same bytes as whole-texture operations (every step is per texel, the 2x bilinear upsampling per pair of
    rows), with about a fifth of the memory at once (a lake's texture is 170 MB; its full-size light, share and
    lit temporaries were 300 MB more). ``consume``: each band's albedo rows go back to the system once lit (the
    albedo reads as zeros after; nothing may use it), and the mips are built after the last band."""
    if consume:
        trim_heap()  # the painting's freed temporaries, before the lit texture is made
    h, w = albedo.shape
    halves = (2 * shadow.shape[0], 2 * shadow.shape[1]) == (h, w) and LIGHT_BAND_ROWS % 2 == 0
    whole = None if halves else _light_maps(shadow, ambient, direct)  # another size: the maps resized whole
    rgba = np.empty((h, w, 4), np.uint8)
    for top in range(0, h, LIGHT_BAND_ROWS):
        bottom = min(h, top + LIGHT_BAND_ROWS)
        if whole is None:  # the shadow rows the band reads, one more on each side (see _upsampled_rows)
            first, end = max(0, top // 2 - 1), min(shadow.shape[0], bottom // 2 + 1)
            light8, share8 = (cv2.resize(low, (w, 2 * (end - first)), interpolation=cv2.INTER_LINEAR)
                              [top - 2 * first:bottom - 2 * first]
                              for low in _light_maps(shadow[first:end], ambient, direct))
        else:
            light8, share8 = (_upsampled_rows(low, (w, h), top, bottom) for low in whole)
        lit = cv2.multiply(albedo.rgb[top:bottom], cv2.cvtColor(light8, cv2.COLOR_GRAY2RGB), scale=1.0 / 128.0)
        band = rgba[top:bottom]
        cv2.cvtColor(lit, cv2.COLOR_RGB2RGBA, dst=band)
        band[..., 3] = share8
        del light8, share8, lit  # before the next band's: one band's temporaries at a time
        if consume:
            _give_back(albedo.rgb[top:bottom])
            trim_heap()
    del whole
    if consume:
        trim_heap()  # the bands' temporaries, before the mips
    mips: list[np.ndarray] = [rgba]
    for _ in range(MIP_LEVELS - 1):
        mips.append(cv2.pyrDown(mips[-1]))
    bright = ambient + direct
    red, green, blue = (int(min(255, round(c * bright))) for c in albedo.mean_rgb)
    border = (red, green, blue, int(round(255 * direct / bright)))
    return LitGround(mips=tuple(mips), x0=albedo.x0, y1=albedo.y1, res=albedo.res, border=border)


def _light_maps(shadow: np.ndarray, ambient: float, direct: float) -> tuple[np.ndarray, np.ndarray]:
    """The light (x128) and direct-light share (x255) of shadow-map texels, uint8: per texel, so any block of rows
    gives those rows of the whole map's."""
    visible = 1.0 - shadow.astype(np.float32) / 255.0
    light = ambient + direct * visible
    share = direct * visible / light
    return np.clip(light * 128.0, 0, 255).astype(np.uint8), np.round(share * 255.0).astype(np.uint8)


def trim_heap() -> None:
    """Give the C heap's free memory back to the system (glibc's ``malloc_trim``; elsewhere nothing): a world's
    build frees hundreds of MB of temporaries below glibc's raised mmap threshold, which stay in the process."""
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return
    trim(0)


def _give_back(rows: np.ndarray) -> None:
    """Return the whole memory pages inside a C-contiguous block of rows to the system (Linux ``madvise``; elsewhere
    nothing): they read as zeros after. Only for an array nothing else will read."""
    if not (sys.platform.startswith("linux") and rows.flags.c_contiguous):
        return
    page = mmap.PAGESIZE
    start = -(-rows.ctypes.data // page) * page
    end = (rows.ctypes.data + rows.nbytes) // page * page
    if end > start:
        ctypes.CDLL(None).madvise(ctypes.c_void_p(start), ctypes.c_size_t(end - start), mmap.MADV_DONTNEED)


def _upsampled_rows(low: np.ndarray, size: tuple[int, int], top: int, bottom: int) -> np.ndarray:
    """Rows ``top:bottom`` of ``cv2.resize(low, size)`` (bilinear). At exactly twice the size (the shadow map's
    case) from the source rows they read, one more on each side: bilinear weights repeat every two rows, so the
    rows are the same bytes as the whole resize's; any other size resizes the whole image."""
    w, h = size
    if (2 * low.shape[0], 2 * low.shape[1]) != (h, w) or top % 2 or (bottom % 2 and bottom != h):
        return cv2.resize(low, size, interpolation=cv2.INTER_LINEAR)[top:bottom]
    first, end = max(0, top // 2 - 1), min(low.shape[0], bottom // 2 + 1)
    rows = cv2.resize(low[first:end], (w, 2 * (end - first)), interpolation=cv2.INTER_LINEAR)
    return rows[top - 2 * first:bottom - 2 * first]


def _prop_visibility(props: Props, shadow: np.ndarray, albedo: GroundAlbedo, sun: Sun) -> dict[str, np.ndarray]:
    """Sun visibility (0..1) of each prop, sampled from the shadow map just sunward of its base."""
    res = albedo.res * SHADOW_DOWNSCALE
    toward = sun.horizontal

    def sample(xy: np.ndarray, clearance: np.ndarray | float) -> np.ndarray:
        if len(xy) == 0:
            return np.zeros(0)
        p = xy + np.outer(np.broadcast_to(clearance, len(xy)), toward)
        u = np.clip(((p[:, 0] - albedo.x0) / res).astype(np.int64), 0, shadow.shape[1] - 1)
        v = np.clip(((albedo.y1 - p[:, 1]) / res).astype(np.int64), 0, shadow.shape[0] - 1)
        return 1.0 - shadow[v, u].astype(np.float64) / 255.0

    t = props.trees
    return {
        "trees": sample(t[:, [TX, TY]], np.where(t[:, TKIND] > 0, 1.0, 0.6) if len(t) else 0.0),
        "poles": sample(props.poles[:, :2], 0.3),
        "cones": sample(props.cones, 0.5),
    }
