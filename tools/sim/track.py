"""Tracks as data: load, validate and query a closed road described by a small JSON file.

A track file gives a handful of centre-line control points; they are smoothed by a periodic cubic
spline (C2, so curvature is continuous and a kinematic vehicle can follow it) and resampled every
~0.5 m. Everything else in the simulator (rendering, rules, autopilot) works on the resampled line,
so every query here is a cheap array lookup. The file format is documented in :func:`parse_track`.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
SAMPLE_SPACING = 0.5  # metres between resampled centre-line points
SURFACE_KINDS = ("asphalt", "bridge", "dirt")
THEMES = ("meadow", "forest")
MIN_TURN_RADIUS = 6.0  # metres: a 2.7 m wheelbase at 25 degrees turns on ~5.8 m
CONE_RADIUS = 0.25  # metres, base radius of the 0.9 m highway cone the renderer draws
CONE_HEIGHT = 0.9
CONE_START_CLEARANCE = 30.0  # metres of clear road either side of the start line

_TOP_KEYS = {"name", "version", "description", "centerline", "road_width", "lanes", "shoulder_width",
             "surfaces", "scenery", "sun", "start", "camera_jitter"}
_REQUIRED = ("name", "version", "centerline", "road_width")


class TrackError(ValueError):
    """A track file (or dict) is missing something or describes a road that cannot be driven."""


@dataclass(frozen=True)
class Surface:
    """A stretch of road from ``from_s`` to ``to_s`` (metres, may wrap past the start) of one kind."""

    from_s: float
    to_s: float
    kind: str

    def contains(self, s: float, length: float) -> bool:
        a, b, s = self.from_s % length, self.to_s % length, s % length
        return a <= s < b if a <= b else (s >= a or s < b)


@dataclass(frozen=True)
class TreeSpec:
    count: int = 0
    seed: int = 0
    min_offset: float = 7.0  # metres from the centre line
    max_offset: float = 40.0
    min_height: float = 4.0  # total height, metres
    max_height: float = 9.0


@dataclass(frozen=True)
class PoleSpec:
    spacing: float = 35.0  # metres along the line; 0 disables
    offset: float = -5.5  # metres from the centre line, signed like cte (+ = left); -: outside of a CCW loop
    height: float = 6.0


@dataclass(frozen=True)
class WaterSpec:
    """An elliptic pond; the road crossing it should be a bridge surface."""

    center: tuple[float, float]
    radius: tuple[float, float]
    angle_deg: float = 0.0


@dataclass(frozen=True)
class Scenery:
    theme: str = "meadow"
    trees: TreeSpec = field(default_factory=TreeSpec)
    poles: PoleSpec = field(default_factory=lambda: PoleSpec(spacing=0.0))
    water: tuple[WaterSpec, ...] = ()
    kerbs: bool = False  # red/white kerbs on the inside of sharp curves


@dataclass(frozen=True)
class CameraJitter:
    """Standard deviation of per-frame camera pitch/roll noise, imitating a bumpy road on flat ground."""

    pitch_deg: float = 0.0
    roll_deg: float = 0.0


@dataclass(frozen=True)
class Projection:
    s: float  # arc length of the closest centre-line point, [0, length)
    cte: float  # signed cross-track error, metres, + = left of the centre line
    heading_rad: float  # centre-line heading at s (world frame, x east, y north, counter-clockwise)


@dataclass(frozen=True, eq=False)
class Track:
    """A validated, resampled closed track; immutable, so Worlds can be cached by :attr:`digest`."""

    name: str
    road_width: float
    lanes: int
    shoulder_width: float
    surfaces: tuple[Surface, ...]
    scenery: Scenery
    sun_azimuth_deg: float
    sun_elevation_deg: float
    start_s: float
    camera_jitter: CameraJitter
    centerline: np.ndarray  # (N, 2) float64, closed, first point not repeated
    tangents: np.ndarray  # (N, 2) unit
    normals: np.ndarray  # (N, 2) unit, pointing left of the driving direction
    curvature: np.ndarray  # (N,) signed 1/m, + = turning left
    s: np.ndarray  # (N,) arc length at each point
    length: float
    source: str
    description: str = ""
    digest: str = ""  # hash of the parsed definition: equal digests draw identical worlds

    def __post_init__(self) -> None:
        for arr in (self.centerline, self.tangents, self.normals, self.curvature, self.s):
            arr.flags.writeable = False

    @property
    def spacing(self) -> float:
        return self.length / len(self.s)

    @property
    def min_radius(self) -> float:
        return float(1.0 / max(np.abs(self.curvature).max(), 1e-9))

    def point_at(self, s: float) -> tuple[float, float, float]:
        """Centre-line point and heading at arc length ``s`` (wraps modulo the length)."""
        s = float(s) % self.length
        u = s / self.spacing
        i = int(u) % len(self.s)
        j = (i + 1) % len(self.s)
        f = u - int(u)
        p = self.centerline[i] * (1 - f) + self.centerline[j] * f
        t = self.tangents[i] * (1 - f) + self.tangents[j] * f
        return float(p[0]), float(p[1]), math.atan2(t[1], t[0])

    def project(self, x: float, y: float, hint_s: float | None = None) -> Projection:
        """Closest centre-line point to (x, y): arc length, signed cross-track error and heading.

        ``hint_s`` (the previous answer) restricts the search to +-25 m around it, which is what a
        vehicle stepping along the road needs and avoids snapping to a nearby parallel stretch.
        """
        n = len(self.s)
        p = np.array([x, y], dtype=np.float64)
        if hint_s is not None:
            w = int(25.0 / self.spacing)
            idx = (int(round((hint_s % self.length) / self.spacing)) + np.arange(-w, w + 1)) % n
            d2 = ((self.centerline[idx] - p) ** 2).sum(1)
            k = int(np.argmin(d2))
            if d2[k] > (2.0 * self.road_width) ** 2 or k in (0, len(idx) - 1):  # lost: search everywhere
                hint_s = None
            else:
                i = int(idx[k])
        if hint_s is None:
            i = int(np.argmin(((self.centerline - p) ** 2).sum(1)))
        # refine on the segment before or after the closest sample
        best = None
        for a in ((i - 1) % n, i):
            b = (a + 1) % n
            seg = self.centerline[b] - self.centerline[a]
            f = float(np.clip(np.dot(p - self.centerline[a], seg) / np.dot(seg, seg), 0.0, 1.0))
            q = self.centerline[a] + f * seg
            d2 = float(((p - q) ** 2).sum())
            if best is None or d2 < best[0]:
                best = (d2, a, b, f, q)
        _, a, b, f, q = best
        t = self.tangents[a] * (1 - f) + self.tangents[b] * f
        t /= np.linalg.norm(t)
        nrm = np.array([-t[1], t[0]])
        s = (self.s[a] + f * self.spacing) % self.length
        return Projection(float(s), float(np.dot(p - q, nrm)), math.atan2(t[1], t[0]))

    def surface_at(self, s: float) -> str:
        """Surface kind under arc length ``s``; later entries in the file win over earlier ones."""
        for surf in reversed(self.surfaces):
            if surf.contains(s, self.length):
                return surf.kind
        return "asphalt"

    def surface_kinds(self) -> np.ndarray:
        """Surface kind index (into :data:`SURFACE_KINDS`) of every resampled point."""
        out = np.zeros(len(self.s), np.int8)
        for surf in self.surfaces:
            a, b = surf.from_s % self.length, surf.to_s % self.length
            m = (self.s >= a) & (self.s < b) if a <= b else (self.s >= a) | (self.s < b)
            out[m] = SURFACE_KINDS.index(surf.kind)
        return out


# ---------------------------------------------------------------------------------------------- loading


def builtin_tracks() -> list[str]:
    """Names of the tracks shipped in ``tools/sim/tracks``."""
    folder = resources.files("tools.sim") / "tracks"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".json"))


def load_track(name_or_path: str | Path) -> Track:
    """Load a built-in track by name (``lake``, ``mountain``) or any track file by path."""
    text = str(name_or_path)
    if isinstance(name_or_path, str) and text in builtin_tracks():
        res = resources.files("tools.sim") / "tracks" / f"{text}.json"
        return _load_text(res.read_text(encoding="utf-8"), f"builtin:{text}")
    path = Path(name_or_path)
    if not path.is_file():
        raise TrackError(f"{path}: no such track file (built-in tracks: {', '.join(builtin_tracks())})")
    return _load_text(path.read_text(encoding="utf-8"), str(path))


def _load_text(text: str, source: str) -> Track:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TrackError(f"{source}: not valid JSON ({exc})") from None
    return parse_track(data, source)


def parse_track(data: Any, source: str = "<dict>") -> Track:
    """Validate a decoded track definition and build the :class:`Track`.

    Keys: ``name``, ``version`` (1), ``centerline`` ([[x, y], ...] metres, at least 4 points, closed,
    driving direction = point order), ``road_width`` (edge line to edge line) are required;
    ``description``, ``lanes`` (1, or 2 with a dashed centre line), ``shoulder_width``, ``surfaces``
    ([{from_s, to_s, kind}]), ``scenery`` ({theme, trees, poles, water, kerbs}), ``sun``
    ({azimuth_deg, elevation_deg}), ``start`` ({s}) and ``camera_jitter`` ({pitch_deg, roll_deg}) are
    optional. Every problem raises :class:`TrackError` naming ``source``.
    """
    r = _Reader(source)
    if not isinstance(data, dict):
        r.fail(f"top level must be a JSON object, got {type(data).__name__}")
    for key in _REQUIRED:
        if key not in data:
            r.fail(f"missing key {key!r}")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        r.fail(f"unknown key(s) {', '.join(map(repr, unknown))} (allowed: {', '.join(sorted(_TOP_KEYS))})")
    if data["version"] != FORMAT_VERSION:
        r.fail(f"unsupported version {data['version']!r} (this simulator reads version {FORMAT_VERSION})")
    name = data["name"]
    if not isinstance(name, str) or not name:
        r.fail("'name' must be a non-empty string")
    road_width = r.number(data, "road_width", lo=2.0, hi=30.0)
    lanes = data.get("lanes", 1)
    if lanes not in (1, 2) or isinstance(lanes, bool):
        r.fail(f"'lanes' must be 1 or 2, got {lanes!r}")
    shoulder = r.number(data, "shoulder_width", 1.0, lo=0.0, hi=10.0)
    control = _control_points(data["centerline"], r)

    pts, tan, curv, length = _resample(control)
    s = np.arange(len(pts)) * (length / len(pts))
    normals = np.stack([-tan[:, 1], tan[:, 0]], 1)
    need = max(MIN_TURN_RADIUS, road_width / 2 + shoulder + 1.0)
    k = int(np.argmax(np.abs(curv)))
    if 1.0 / max(abs(curv[k]), 1e-12) < need:
        r.fail(f"curve radius {1 / abs(curv[k]):.1f} m at s={s[k]:.0f} m (near x={pts[k, 0]:.1f}, "
               f"y={pts[k, 1]:.1f}) is below the {need:.1f} m this road width and shoulder need")
    _check_overlap(pts, s, length, road_width + 2 * shoulder, r)

    surfaces = tuple(_surface(item, i, length, r) for i, item in enumerate(r.list(data, "surfaces")))
    scenery = _scenery(r.obj(data, "scenery"), r)
    sun = r.obj(data, "sun")
    r.keys(sun, "sun", {"azimuth_deg", "elevation_deg"})
    start = r.obj(data, "start")
    r.keys(start, "start", {"s"})
    jit = r.obj(data, "camera_jitter")
    r.keys(jit, "camera_jitter", {"pitch_deg", "roll_deg"})
    digest = hashlib.sha1(json.dumps({k: data[k] for k in sorted(data) if k != "description"},
                                     sort_keys=True).encode()).hexdigest()[:16]
    return Track(
        name=name, road_width=road_width, lanes=int(lanes), shoulder_width=shoulder, surfaces=surfaces,
        scenery=scenery,
        sun_azimuth_deg=r.number(sun, "azimuth_deg", 220.0, lo=-360.0, hi=360.0, where="sun"),
        sun_elevation_deg=r.number(sun, "elevation_deg", 40.0, lo=5.0, hi=90.0, where="sun"),
        start_s=r.number(start, "s", 0.0, where="start") % length,
        camera_jitter=CameraJitter(r.number(jit, "pitch_deg", 0.0, lo=0.0, hi=10.0, where="camera_jitter"),
                                   r.number(jit, "roll_deg", 0.0, lo=0.0, hi=10.0, where="camera_jitter")),
        centerline=pts, tangents=tan, normals=normals, curvature=curv, s=s, length=float(length),
        source=source, description=str(data.get("description", "")), digest=digest,
    )


class _Reader:
    """Small typed accessors that turn bad values into TrackErrors naming the file."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, problem: str):
        raise TrackError(f"{self.source}: {problem}")

    def number(self, obj: dict, key: str, default: float | None = None, *, lo: float = -math.inf,
               hi: float = math.inf, where: str = "") -> float:
        label = f"{where}.{key}" if where else key
        if key not in obj:
            if default is None:
                self.fail(f"missing key {label!r}")
            return float(default)
        v = obj[key]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            self.fail(f"{label!r} must be a number, got {v!r}")
        if not lo <= v <= hi:
            self.fail(f"{label!r} = {v} is outside [{lo:g}, {hi:g}]")
        return float(v)

    def obj(self, data: dict, key: str) -> dict:
        v = data.get(key, {})
        if not isinstance(v, dict):
            self.fail(f"{key!r} must be a JSON object, got {type(v).__name__}")
        return v

    def list(self, data: dict, key: str) -> list:
        v = data.get(key, [])
        if not isinstance(v, list):
            self.fail(f"{key!r} must be a list, got {type(v).__name__}")
        return v

    def keys(self, obj: dict, where: str, allowed: set[str]) -> None:
        unknown = sorted(set(obj) - allowed)
        if unknown:
            self.fail(f"unknown key(s) {', '.join(map(repr, unknown))} in {where!r} "
                      f"(allowed: {', '.join(sorted(allowed))})")


def _control_points(raw: Any, r: _Reader) -> np.ndarray:
    if not isinstance(raw, list):
        r.fail("'centerline' must be a list of [x, y] points")
    for i, p in enumerate(raw):
        if (not isinstance(p, list | tuple) or len(p) != 2
                or not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in p)):
            r.fail(f"centerline point {i} must be [x, y] with finite numbers, got {p!r}")
    pts = np.asarray(raw, dtype=np.float64).reshape(-1, 2)
    if len(pts) >= 2 and np.allclose(pts[0], pts[-1]):
        log.debug("%s: last centre-line point repeats the first; dropping it", r.source)
        pts = pts[:-1]
    if len(pts) < 4:
        r.fail(f"centerline needs at least 4 points for a closed loop, got {len(pts)}")
    step = np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)
    if step.min() < 1e-3:
        i = int(np.argmin(step))
        r.fail(f"centerline points {i} and {(i + 1) % len(pts)} coincide")
    return pts


def _periodic_spline(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Chord-length knots and second derivatives of the C2 periodic cubic spline through ``pts``."""
    n = len(pts)
    h = np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)  # h[i]: knot i -> i+1
    hp = np.roll(h, 1)  # h[i-1]
    a = np.zeros((n, n))
    idx = np.arange(n)
    a[idx, (idx - 1) % n] += hp
    a[idx, idx] += 2 * (hp + h)
    a[idx, (idx + 1) % n] += h
    slope = (np.roll(pts, -1, 0) - pts) / h[:, None]
    rhs = 6 * (slope - np.roll(slope, 1, 0))
    m = np.linalg.solve(a, rhs)
    return h, m


def _eval_spline(pts: np.ndarray, h: np.ndarray, m: np.ndarray, t: np.ndarray):
    """Position, first and second derivative at global parameters ``t`` in [0, sum(h))."""
    knots = np.concatenate([[0.0], np.cumsum(h)])
    i = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(h) - 1)
    hi = h[i][:, None]
    u = (t - knots[i])[:, None]
    v = hi - u
    p0, p1 = pts[i], pts[(i + 1) % len(pts)]
    m0, m1 = m[i], m[(i + 1) % len(pts)]
    pos = m0 * v**3 / (6 * hi) + m1 * u**3 / (6 * hi) + (p0 / hi - m0 * hi / 6) * v + (p1 / hi - m1 * hi / 6) * u
    d1 = -m0 * v**2 / (2 * hi) + m1 * u**2 / (2 * hi) - (p0 / hi - m0 * hi / 6) + (p1 / hi - m1 * hi / 6)
    d2 = m0 * v / hi + m1 * u / hi
    return pos, d1, d2


def _resample(control: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Resample the smoothed loop every ~SAMPLE_SPACING metres; return points, tangents, curvature, length."""
    h, m = _periodic_spline(control)
    total = float(h.sum())
    dense_t = np.linspace(0.0, total, max(int(total / 0.05), 400), endpoint=False)
    pos, _, _ = _eval_spline(control, h, m, dense_t)
    seg = np.linalg.norm(np.roll(pos, -1, 0) - pos, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    length = float(cum[-1])
    n = max(int(round(length / SAMPLE_SPACING)), 8)
    target = np.arange(n) * (length / n)
    t = np.interp(target, cum, np.concatenate([dense_t, [total]]))
    pts, d1, d2 = _eval_spline(control, h, m, t)
    speed = np.linalg.norm(d1, axis=1)
    tan = d1 / speed[:, None]
    curv = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / speed**3
    return pts, tan, curv, length


def _check_overlap(pts: np.ndarray, s: np.ndarray, length: float, clearance: float, r: _Reader) -> None:
    """Fail when two stretches of road (shoulders included) overlap or the centre line crosses itself.

    Points further apart along the line than pi/2 * clearance must be at least ``clearance`` apart in
    space; with curve radii >= clearance / 2 (checked before) closer pairs are always far enough apart.
    """
    step = max(1, int(1.0 / (length / len(pts))))  # check on a ~1 m grid
    p, ss = pts[::step], s[::step]
    gap = math.pi / 2 * clearance
    for lo in range(0, len(p), 512):
        d = np.linalg.norm(p[lo:lo + 512, None] - p[None], axis=2)
        along = np.abs(ss[lo:lo + 512, None] - ss[None])
        along = np.minimum(along, length - along)
        bad = (along > gap) & (d < clearance - 1e-6)
        if bad.any():
            i, j = np.unravel_index(int(np.argmin(np.where(bad, d, np.inf))), d.shape)
            i += lo
            what = "crosses itself" if d[i - lo, j] < 0.5 else "overlaps itself"
            r.fail(f"road {what} near s={ss[i]:.0f} m and s={ss[j]:.0f} m (x={p[i, 0]:.1f}, y={p[i, 1]:.1f}): "
                   f"centre lines {d[i - lo, j]:.1f} m apart, road plus shoulders need {clearance:.1f} m")


def _surface(item: Any, i: int, length: float, r: _Reader) -> Surface:
    if not isinstance(item, dict):
        r.fail(f"surfaces[{i}] must be an object with from_s, to_s, kind")
    r.keys(item, f"surfaces[{i}]", {"from_s", "to_s", "kind"})
    kind = item.get("kind", "asphalt")
    if kind not in SURFACE_KINDS:
        r.fail(f"surfaces[{i}]: unknown surface kind {kind!r} (known: {', '.join(SURFACE_KINDS)})")
    a = r.number(item, "from_s", lo=0.0, where=f"surfaces[{i}]")
    b = r.number(item, "to_s", lo=0.0, where=f"surfaces[{i}]")
    if a > length + 1e-6 or b > length + 1e-6:
        r.fail(f"surfaces[{i}]: from_s/to_s must lie within the track length {length:.1f} m")
    if a == b:
        r.fail(f"surfaces[{i}]: from_s equals to_s (empty stretch)")
    return Surface(a, b, kind)


def _scenery(raw: dict, r: _Reader) -> Scenery:
    r.keys(raw, "scenery", {"theme", "trees", "poles", "water", "kerbs"})
    theme = raw.get("theme", "meadow")
    if theme not in THEMES:
        r.fail(f"scenery.theme: unknown theme {theme!r} (known: {', '.join(THEMES)})")
    t = r.obj(raw, "trees")
    r.keys(t, "scenery.trees", {"count", "seed", "min_offset", "max_offset", "min_height", "max_height"})
    w = "scenery.trees"
    trees = TreeSpec(
        count=int(r.number(t, "count", 0, lo=0, hi=5000, where=w)), seed=int(r.number(t, "seed", 0, where=w)),
        min_offset=r.number(t, "min_offset", 7.0, lo=0.0, where=w),
        max_offset=r.number(t, "max_offset", 40.0, lo=0.0, hi=500.0, where=w),
        min_height=r.number(t, "min_height", 4.0, lo=1.0, hi=40.0, where=w),
        max_height=r.number(t, "max_height", 9.0, lo=1.0, hi=40.0, where=w))
    if trees.max_offset < trees.min_offset or trees.max_height < trees.min_height:
        r.fail("scenery.trees: max_offset/max_height must not be below min_offset/min_height")
    p = r.obj(raw, "poles")
    r.keys(p, "scenery.poles", {"spacing", "offset", "height"})
    poles = PoleSpec(spacing=r.number(p, "spacing", 0.0, lo=0.0, where="scenery.poles"),
                     offset=r.number(p, "offset", -5.5, where="scenery.poles"),
                     height=r.number(p, "height", 6.0, lo=1.0, hi=30.0, where="scenery.poles"))
    water = []
    for i, item in enumerate(r.list(raw, "water")):
        where = f"scenery.water[{i}]"
        if not isinstance(item, dict):
            r.fail(f"{where} must be an object with center, radius, angle_deg")
        r.keys(item, where, {"center", "radius", "angle_deg"})
        pair = []
        for key in ("center", "radius"):
            v = item.get(key)
            if (not isinstance(v, list) or len(v) != 2
                    or not all(isinstance(c, int | float) and not isinstance(c, bool) for c in v)):
                r.fail(f"{where}.{key} must be [a, b] numbers, got {v!r}")
            pair.append((float(v[0]), float(v[1])))
        if min(pair[1]) <= 0:
            r.fail(f"{where}.radius must be positive")
        water.append(WaterSpec(pair[0], pair[1], r.number(item, "angle_deg", 0.0, where=where)))
    kerbs = raw.get("kerbs", False)
    if not isinstance(kerbs, bool):
        r.fail(f"scenery.kerbs must be true or false, got {kerbs!r}")
    return Scenery(theme=theme, trees=trees, poles=poles, water=tuple(water), kerbs=kerbs)


# ---------------------------------------------------------------------------------------------- obstacles


def place_cones(track: Track, n: int, seed: int, min_spacing: float = 25.0) -> np.ndarray:
    """Positions (n, 2) of ``n`` traffic cones, each blocking about half the road.

    Each cone stands in the middle of one half of the road (``road_width / 4`` off the centre line, side
    drawn at random), so the gap to that edge is narrower than a car and it must pass on the other half.
    Cones are stratified along the track (one per equal slot, jittered inside it) so placements are
    ``min_spacing`` apart, never within :data:`CONE_START_CLEARANCE` of the start; the same seed always
    gives the same cones, a different seed new positions.
    """
    if n < 0:
        raise ValueError(f"number of cones must be >= 0, got {n}")
    if n == 0:
        return np.zeros((0, 2))
    usable = track.length - 2 * CONE_START_CLEARANCE
    slot = usable / n
    if slot < min_spacing:
        raise ValueError(f"{n} cones {min_spacing:g} m apart do not fit on {track.name!r} "
                         f"({usable:.0f} m usable); use fewer cones")
    rng = np.random.default_rng(seed)
    along = track.start_s + CONE_START_CLEARANCE + slot * np.arange(n) + rng.uniform(0, slot - min_spacing, n)
    side = rng.choice([-1.0, 1.0], n)
    out = np.empty((n, 2))
    for k, (s, sgn) in enumerate(zip(along, side, strict=True)):
        x, y, heading = track.point_at(s)
        off = sgn * track.road_width / 4
        out[k] = (x - math.sin(heading) * off, y + math.cos(heading) * off)
    return out
