"""Everything but the centre line: surfaces, edges, water and bridges, scenery, sun, sky and camera look.

Each choice is one draw from the world's generator, in a fixed order, so a seed always dresses its
road the same way. Probabilities are data at the top of each function; the README lists them.
"""

from __future__ import annotations

import math

import numpy as np

from tools.sim.track.themes import PALETTES, SKIES, UDACITY_THEMES
from tools.sim.worldgen.layout import DS, Layout

COLOURED = ("ground", "ground2", "shoulder", "dirt", "water")  # the rest are greys: little hue change
BASE_SURFACES = (("asphalt", 0.5), ("worn_asphalt", 0.15), ("concrete", 0.12), ("dirt", 0.12), ("gravel", 0.11))
TREE_HEIGHTS = {"desert": (1.5, 4.0), "forest": (8.0, 17.0), "snow": (6.0, 14.0), "rocky": (3.0, 10.0),
                "udacity_lake": (5.0, 14.0), "udacity_jungle": (6.0, 16.0)}
#: Markings of the Udacity-like themes, as on the real tracks: the lake's yellow edge lines and light
#: concrete kerb strip, the jungle's white edge lines and dashed white centre line, the mountain's bare
#: road between leaf-strewn verges. (Generic themes draw theirs at random.)
UDACITY_EDGES = {
    "udacity_lake": {"line_color": "yellow", "line_style": "solid", "center_color": "yellow",
                     "center_style": "none", "verge": "concrete"},
    "udacity_jungle": {"line_color": "white", "line_style": "solid", "center_color": "white",
                       "center_style": "dashed", "verge": "grass"},
    "udacity_mountain": {"line_color": "yellow", "line_style": "none", "center_color": "white",
                         "center_style": "none", "verge": "shoulder"},
}
#: Red-and-white kerbs on sharp curves: share of worlds (the real lake has them on most curves).
KERB_SHARE = {"udacity_lake": 0.8}
#: Fine texture grain of the ground, per theme (the real tracks' asphalt is coarse; the lake's near road
#: matched the real one's edge density at about 3x, docs/results.md: rbc realism).
GRAIN = {"udacity_lake": (2.0, 3.0), "udacity_jungle": (1.0, 2.5), "udacity_mountain": (1.5, 3.0)}
DENSITY_PER_KM = (("bare", 0.12, 0, 0), ("sparse", 0.33, 30, 120), ("medium", 0.33, 120, 320),
                  ("dense", 0.22, 320, 650))


def _pick(rng: np.random.Generator, table) -> str:
    names, p = zip(*[(row[0], row[1]) for row in table], strict=True)
    return str(rng.choice(names, p=np.asarray(p) / sum(p)))


def _jitter_rgb(rng: np.random.Generator, rgb, spread: float, chroma: float = 0.5) -> list[int]:
    """Brightness varied by +-spread, each channel by +-spread * chroma more."""
    gain = rng.uniform(1 - spread, 1 + spread) * rng.uniform(1 - spread * chroma, 1 + spread * chroma, 3)
    return [int(np.clip(round(c * g), 0, 255)) for c, g in zip(rgb, gain, strict=True)]


def surfaces(rng: np.random.Generator, length: float, theme: str) -> list[dict]:
    """A base kind for the whole loop and up to four stretches of other kinds (Udacity-like: asphalt only)."""
    if theme in UDACITY_THEMES:
        return []
    base = _pick(rng, BASE_SURFACES)
    out = [{"from_s": 0.0, "to_s": round(length - 0.01, 2), "kind": base}] if base != "asphalt" else []
    for _ in range(int(rng.choice([0, 0, 1, 2, 3, 4]))):
        kind = _pick(rng, [k for k in BASE_SURFACES if k[0] != base])
        a = float(rng.uniform(0, length))
        b = (a + float(rng.uniform(30, 180))) % length
        out.append({"from_s": round(a, 2), "to_s": round(b, 2), "kind": kind})
    return out


def edges(rng: np.random.Generator, theme: str) -> dict:
    if theme in UDACITY_EDGES:
        return {**UDACITY_EDGES[theme], "barriers": bool(rng.uniform() < 0.35)}
    return {"line_color": str(rng.choice(["white", "yellow"], p=[0.7, 0.3])),
            "line_style": str(rng.choice(["solid", "dashed", "none"], p=[0.6, 0.2, 0.2])),
            "center_color": str(rng.choice(["theme", "white", "yellow"], p=[0.4, 0.3, 0.3])),
            "center_style": str(rng.choice(["dashed", "solid", "none"], p=[0.6, 0.25, 0.15])),
            "verge": str(rng.choice(["shoulder", "grass", "sand", "dirt", "gravel"], p=[0.3, 0.2, 0.15, 0.2, 0.15])),
            "barriers": bool(rng.uniform() < 0.35)}


def _ellipse_ok(lay: Layout, centre, radius, angle_deg: float, keep_off: float, skip: tuple[float, float] | None):
    """Whether the ellipse grown by ``keep_off`` metres holds no centre-line point outside ``skip``."""
    pts = lay.points[::4]
    if skip is not None:
        s = np.arange(len(pts)) * DS * 4
        length = len(lay.points) * DS
        pts = pts[((s - skip[0]) % length) >= ((skip[1] - skip[0]) % length)]
    a = math.radians(angle_deg)
    rel = pts - np.asarray(centre)
    u = rel[:, 0] * math.cos(a) + rel[:, 1] * math.sin(a)
    v = -rel[:, 0] * math.sin(a) + rel[:, 1] * math.cos(a)
    return bool(((u / (radius[0] + keep_off)) ** 2 + (v / (radius[1] + keep_off)) ** 2).min() > 1.0)


def water(rng: np.random.Generator, lay: Layout, theme: str, keep_off: float, half_deck: float):
    """Ponds beside the road and at most one crossed by a bridge: (water specs, bridge surfaces)."""
    ponds: list[dict[str, object]] = []
    bridges = []
    length = len(lay.points) * DS
    n_side = int(rng.integers(2, 6)) if theme == "wetland" else int(rng.choice([0, 0, 1, 2]))
    for _ in range(n_side * 4):  # a few tries each
        if len(ponds) >= n_side:
            break
        i = int(rng.integers(len(lay.points)))
        tan = lay.points[(i + 1) % len(lay.points)] - lay.points[i]
        nrm = np.array([-tan[1], tan[0]]) / max(np.linalg.norm(tan), 1e-9)
        r = (float(rng.uniform(10, 45)), float(rng.uniform(8, 30)))
        c = lay.points[i] + nrm * rng.choice([-1, 1]) * (keep_off + max(r) + rng.uniform(3, 25))
        ang = float(rng.uniform(0, 180))
        if _ellipse_ok(lay, c, r, ang, keep_off, None):
            ponds.append({"center": [round(float(c[0]), 2), round(float(c[1]), 2)],
                          "radius": [round(r[0], 2), round(r[1], 2)], "angle_deg": round(ang, 1)})
    if rng.uniform() < (0.7 if theme == "wetland" else 0.3):  # a bridge over a pond on a straight stretch
        flat = np.abs(lay.curvature) < 1 / 150
        for _ in range(12):
            i = int(rng.integers(len(lay.points)))
            along = float(rng.uniform(7, 18))
            span = int((along + keep_off + 6) / DS)
            if not flat[np.arange(i - span, i + span) % len(flat)].all() or abs(i * DS - lay.start_s) < 60:
                continue
            tan = lay.points[(i + 1) % len(lay.points)] - lay.points[i - 1]
            ang = math.degrees(math.atan2(tan[1], tan[0]))
            r = (along, float(rng.uniform(half_deck + 6, 35)))
            reach = along + keep_off + 2  # the deck spans the pond and its keep-off margin
            skip = ((i * DS - reach) % length, (i * DS + reach) % length)
            if _ellipse_ok(lay, lay.points[i], r, ang, keep_off, skip):
                c = lay.points[i]
                ponds.append({"center": [round(float(c[0]), 2), round(float(c[1]), 2)],
                              "radius": [round(r[0], 2), round(r[1], 2)], "angle_deg": round(ang, 1)})
                bridges.append({"from_s": round(skip[0], 2), "to_s": round(skip[1], 2), "kind": "bridge"})
                break
    return ponds, bridges


def scenery(rng: np.random.Generator, theme: str, length: float, edge: float) -> dict:
    name = _pick(rng, DENSITY_PER_KM)
    lo, hi = next((r[2], r[3]) for r in DENSITY_PER_KM if r[0] == name)
    count = int(rng.uniform(lo, hi) * length / 1000) if hi else 0
    h_lo, h_hi = TREE_HEIGHTS.get(theme, (4.0, 12.0))
    near = edge + float(rng.uniform(1.5, 6.0))
    out = {"theme": theme, "kerbs": bool(rng.uniform() < KERB_SHARE.get(theme, 0.3)),
           "trees": {"count": count, "seed": int(rng.integers(2**31)), "min_offset": round(near, 2),
                     "max_offset": round(near + float(rng.uniform(15, 60)), 2),
                     "min_height": h_lo, "max_height": h_hi}}
    if rng.uniform() < 0.3:
        out["poles"] = {"spacing": round(float(rng.uniform(25, 50)), 1),
                        "offset": round(float(rng.choice([-1, 1]) * (edge + rng.uniform(0.8, 2.0))), 2),
                        "height": round(float(rng.uniform(5, 8)), 1)}
    return out


def sky(rng: np.random.Generator, theme: str) -> dict:
    base = SKIES[theme]
    return {"seed": int(rng.integers(2**31)), "clouds": round(float(rng.beta(1.3, 1.6)), 3),
            "zenith": _jitter_rgb(rng, base.zenith, 0.08), "haze": _jitter_rgb(rng, base.haze, 0.05)}


def appearance(rng: np.random.Generator, theme: str) -> dict:
    """Per-world palette and camera: moderate, so every world still looks like a plausible road."""
    pal = PALETTES[theme]
    keys = ("ground", "ground2", "shoulder", "asphalt", "worn", "concrete", "dirt", "gravel", "water")
    t = float(rng.uniform(-0.08, 0.08))  # colour temperature: warm (+) or cool (-)
    blur = 0.0 if rng.uniform() < 0.5 else float(rng.uniform(0.3, 1.1))
    noise = 0.0 if rng.uniform() < 0.4 else float(rng.uniform(0.5, 4.0))
    return {"seed": int(rng.integers(2**31)),
            "palette": {k: _jitter_rgb(rng, pal[k], 0.12, 0.5 if k in COLOURED else 0.12) for k in keys},
            "grain": round(float(rng.uniform(*GRAIN.get(theme, (0.5, 1.6)))), 3),
            "texture_scale": round(float(rng.uniform(0.6, 2.0)), 3),
            "exposure_ev": round(float(np.clip(rng.normal(0, 0.25), -0.6, 0.6)), 3),
            "contrast": round(float(rng.uniform(0.85, 1.2)), 3),
            "white_balance": [round(1 + t, 3), round(1 + float(rng.uniform(-0.03, 0.03)), 3), round(1 - t, 3)],
            "haze": round(float(math.exp(rng.uniform(math.log(0.5), math.log(2.5)))), 3),
            "blur": round(blur, 3), "noise": round(noise, 2), "jpeg_quality": int(rng.integers(55, 96)),
            "jitter": {"exposure_ev": round(float(rng.uniform(0, 0.08)), 3),
                       "contrast": round(float(rng.uniform(0, 0.03)), 3),
                       "white_balance": round(float(rng.uniform(0, 0.02)), 3),
                       "noise": round(float(rng.uniform(0, 1.0)), 2)}}
