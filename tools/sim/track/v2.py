"""Track format version 2: the ``edges``, ``sky`` and ``appearance`` objects (see :mod:`tools.sim.track.looks`).

Version 2 also admits the surface kinds and themes that came with it (concrete, gravel, worn asphalt;
desert, autumn, snow, rocky, wetland). Each key is optional and defaults to what version 1 draws.

``edges``: ``line_color`` (white, yellow), ``line_style`` (solid, dashed, none), ``center_color``
(theme, white, yellow), ``center_style`` (dashed, solid, none), ``verge`` (shoulder, grass, sand,
dirt, gravel), ``barriers`` (bool: guard rails outside sharp curves).
``sky``: ``seed`` (cloud noise), ``clouds`` (0 clear .. 1 overcast), ``zenith``/``haze`` ([r, g, b]).
``appearance``: ``seed`` (ground texture noise), ``palette`` ({entry: [r, g, b]}), ``grain``,
``texture_scale``, ``exposure_ev``, ``contrast``, ``white_balance`` ([r, g, b] gains), ``haze`` (fog
density factor), ``blur`` (sigma px), ``noise`` (grey levels), ``jpeg_quality`` and ``jitter``
({exposure_ev, contrast, white_balance, noise}: per-frame standard deviations).
"""

from __future__ import annotations

from tools.sim.track.looks import (
    CENTER_COLORS,
    LINE_COLORS,
    LINE_STYLES,
    VERGES,
    Appearance,
    Edges,
    FrameJitter,
    SkySpec,
)
from tools.sim.track.reader import Reader
from tools.sim.track.themes import PALETTES

V2_KEYS = {"edges", "sky", "appearance"}


def _choice(r: Reader, obj: dict, key: str, allowed: tuple[str, ...], default: str, where: str) -> str:
    v = obj.get(key, default)
    if v not in allowed:
        r.fail(f"{where}.{key}: {v!r} is not one of {', '.join(allowed)}")
    return v


def _rgb(r: Reader, v: object, where: str) -> tuple[int, int, int]:
    if (not isinstance(v, list) or len(v) != 3
            or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in v)):
        r.fail(f"{where} must be [r, g, b] integers 0..255, got {v!r}")
    return int(v[0]), int(v[1]), int(v[2])


def parse_edges(raw: dict, r: Reader) -> Edges:
    w = "edges"
    r.keys(raw, w, {"line_color", "line_style", "center_color", "center_style", "verge", "barriers"})
    barriers = raw.get("barriers", False)
    if not isinstance(barriers, bool):
        r.fail(f"edges.barriers must be true or false, got {barriers!r}")
    return Edges(line_color=_choice(r, raw, "line_color", LINE_COLORS, "white", w),
                 line_style=_choice(r, raw, "line_style", LINE_STYLES, "solid", w),
                 center_color=_choice(r, raw, "center_color", CENTER_COLORS, "theme", w),
                 center_style=_choice(r, raw, "center_style", LINE_STYLES, "dashed", w),
                 verge=_choice(r, raw, "verge", VERGES, "shoulder", w), barriers=barriers)


def parse_sky(raw: dict, r: Reader) -> SkySpec:
    r.keys(raw, "sky", {"seed", "clouds", "zenith", "haze"})
    default = SkySpec()
    threshold = default.cloud_threshold
    if "clouds" in raw:
        threshold = 0.65 - r.number(raw, "clouds", lo=0.0, hi=1.0, where="sky")
    return SkySpec(seed=int(r.number(raw, "seed", default.seed, lo=0, hi=2**63 - 1, where="sky")),
                   cloud_threshold=threshold,
                   zenith=_rgb(r, raw["zenith"], "sky.zenith") if "zenith" in raw else None,
                   haze=_rgb(r, raw["haze"], "sky.haze") if "haze" in raw else None)


def parse_appearance(raw: dict, r: Reader) -> Appearance:
    w = "appearance"
    r.keys(raw, w, {"seed", "palette", "grain", "texture_scale", "exposure_ev", "contrast", "white_balance",
                    "haze", "blur", "noise", "jpeg_quality", "jitter"})
    pal = r.obj(raw, "palette")
    known = set(PALETTES["meadow"])
    unknown = sorted(set(pal) - known)
    if unknown:
        r.fail(f"appearance.palette: unknown entries {', '.join(unknown)} (known: {', '.join(sorted(known))})")
    palette = tuple((k, _rgb(r, pal[k], f"appearance.palette.{k}")) for k in sorted(pal))
    wb = raw.get("white_balance", [1.0, 1.0, 1.0])
    if (not isinstance(wb, list) or len(wb) != 3
            or not all(isinstance(c, int | float) and not isinstance(c, bool) and 0.5 <= c <= 2.0 for c in wb)):
        r.fail(f"appearance.white_balance must be three gains in [0.5, 2], got {wb!r}")
    jit = r.obj(raw, "jitter")
    r.keys(jit, "appearance.jitter", {"exposure_ev", "contrast", "white_balance", "noise"})
    wj = "appearance.jitter"
    jitter = FrameJitter(exposure_ev=r.number(jit, "exposure_ev", 0.0, lo=0.0, hi=1.0, where=wj),
                         contrast=r.number(jit, "contrast", 0.0, lo=0.0, hi=0.5, where=wj),
                         white_balance=r.number(jit, "white_balance", 0.0, lo=0.0, hi=0.2, where=wj),
                         noise=r.number(jit, "noise", 0.0, lo=0.0, hi=10.0, where=wj))
    return Appearance(
        seed=int(r.number(raw, "seed", 0, lo=0, hi=2**63 - 1, where=w)), palette=palette,
        grain=r.number(raw, "grain", 1.0, lo=0.0, hi=3.0, where=w),
        texture_scale=r.number(raw, "texture_scale", 1.0, lo=0.25, hi=4.0, where=w),
        exposure_ev=r.number(raw, "exposure_ev", 0.0, lo=-2.0, hi=2.0, where=w),
        contrast=r.number(raw, "contrast", 1.0, lo=0.5, hi=2.0, where=w),
        white_balance=(float(wb[0]), float(wb[1]), float(wb[2])),
        haze=r.number(raw, "haze", 1.0, lo=0.0, hi=10.0, where=w),
        blur=r.number(raw, "blur", 0.0, lo=0.0, hi=3.0, where=w),
        noise=r.number(raw, "noise", 0.0, lo=0.0, hi=20.0, where=w),
        jpeg_quality=int(r.number(raw, "jpeg_quality", 75, lo=10, hi=100, where=w)), jitter=jitter)
