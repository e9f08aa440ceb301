"""The track file format: read, validate and load a JSON track file into a :class:`~tools.sim.track.road.Track`.

The format is documented in :func:`parse_track`; every problem raises :class:`~tools.sim.track.road.TrackError`
naming the file. Tracks are immutable, so each is loaded once per process (:func:`get_track`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
from collections.abc import Mapping
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from protocol.runrecords import write_text
from tools.sim.track.geometry import closest_overlap
from tools.sim.track.reader import Reader
from tools.sim.track.road import (
    MIN_TURN_RADIUS,
    SURFACE_KINDS,
    THEMES,
    V1_SURFACE_KINDS,
    V1_THEMES,
    CameraJitter,
    PoleSpec,
    Scenery,
    Surface,
    Track,
    TrackError,
    TreeSpec,
    WaterSpec,
)
from tools.sim.track.spline import resample_loop
from tools.sim.track.v2 import V2_KEYS, parse_appearance, parse_edges, parse_sky

log = logging.getLogger(__name__)

#: Bounds checked before anything is allocated (a hostile or broken file must not take the machine down).
MAX_CONTROL_POINTS = 2000
MAX_COORDINATE_M = 10_000.0
MAX_LENGTH_M = 20_000.0

FORMAT_VERSION = 2  # what this simulator writes; it reads every version in SUPPORTED_VERSIONS
SUPPORTED_VERSIONS = (1, 2)


_TOP_KEYS = {"name", "version", "description", "centerline", "road_width", "lanes", "shoulder_width",
             "surfaces", "scenery", "sun", "start", "camera_jitter"} | V2_KEYS


_REQUIRED = ("name", "version", "centerline", "road_width")


def track_text(doc: Mapping[str, object]) -> str:
    """A track document as the text of its file: one serialisation, so equal documents give equal files."""
    return json.dumps(doc, indent=1) + "\n"


def write_track_file(path: str | Path, doc: Mapping[str, object]) -> Path:
    """Write a track document (temp file, then rename: a reader never sees half a file), creating its folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, track_text(doc))
    return path


def builtin_tracks() -> list[str]:
    """Names of the tracks shipped in ``tools/sim/track/builtin``."""
    folder = resources.files("tools.sim.track") / "builtin"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".json"))


#: ``--track world:SEED`` names generated world SEED (the world ``rbc world --seed SEED`` writes) in the rbc
#: commands, which write it to a file first (:func:`tools.sim.worldgen.generate.resolve_track_name`).
WORLD_PREFIX = "world:"


def world_seed_of(name: str | Path) -> int | None:
    """The seed of a ``world:SEED`` track name, None for any other name; a malformed one is a TrackError."""
    if not isinstance(name, str) or not name.startswith(WORLD_PREFIX):
        return None
    text = name[len(WORLD_PREFIX):]
    if not text.isdigit() or len(text) > 12:
        raise TrackError(f"{name}: a generated world is named world:SEED with SEED an integer >= 0, e.g. world:1000000")
    return int(text)


def load_track(name_or_path: str | Path) -> Track:
    """Load a built-in track by name (``lake``, ``mountain``) or any track file by path."""
    text = str(name_or_path)
    seed = world_seed_of(name_or_path)
    if seed is not None:  # the generator drives its candidates in the simulator, which loads tracks from here
        raise TrackError(f"{text}: a generated world is loaded from its file: the rbc commands write it for "
                         f"--track world:SEED (tools.sim.worldgen.resolve_track_name), or write_world({seed}, path)")
    if isinstance(name_or_path, str) and text in builtin_tracks():
        res = resources.files("tools.sim.track") / "builtin" / f"{text}.json"
        return _load_text(res.read_text(encoding="utf-8"), f"builtin:{text}")
    path = Path(name_or_path)
    if not path.is_file():
        raise TrackError(f"{path}: no such track file (built-in tracks: {', '.join(builtin_tracks())}; "
                         f"a generated world: world:SEED)")
    return _load_text(path.read_text(encoding="utf-8"), str(path))


def _load_text(text: str, source: str) -> Track:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TrackError(f"{source}: not valid JSON ({exc})") from None
    return parse_track(data, source)


def parse_track(data: object, source: str = "<dict>") -> Track:
    """Validate a decoded track definition and build the :class:`Track`.

    Keys: ``name``, ``version`` (1 or 2), ``centerline`` ([[x, y], ...] metres, at least 4 points, closed,
    driving direction = point order), ``road_width`` (edge line to edge line) are required;
    ``description``, ``lanes`` (1, or 2 with a dashed centre line), ``shoulder_width``, ``surfaces``
    ([{from_s, to_s, kind}]), ``scenery`` ({theme, trees, poles, water, kerbs}), ``sun``
    ({azimuth_deg, elevation_deg}), ``start`` ({s}) and ``camera_jitter`` ({pitch_deg, roll_deg}) are
    optional. Version 2 adds ``edges``, ``sky`` and ``appearance`` and more surface kinds and themes
    (:mod:`tools.sim.track.v2`). Every problem raises :class:`TrackError` naming ``source``.
    """
    r = Reader(source)
    if not isinstance(data, dict):
        r.fail(f"top level must be a JSON object, got {type(data).__name__}")
    for key in _REQUIRED:
        if key not in data:
            r.fail(f"missing key {key!r}")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        r.fail(f"unknown key(s) {', '.join(map(repr, unknown))} (allowed: {', '.join(sorted(_TOP_KEYS))})")
    version = data["version"]
    if isinstance(version, bool) or version not in SUPPORTED_VERSIONS:
        r.fail(f"unsupported version {version!r} (this simulator reads versions "
               f"{', '.join(map(str, SUPPORTED_VERSIONS))})")
    if version == 1 and V2_KEYS & set(data):
        r.fail(f"key(s) {', '.join(sorted(V2_KEYS & set(data)))} need \"version\": 2")
    name = data["name"]
    if not isinstance(name, str) or not name:
        r.fail("'name' must be a non-empty string")
    road_width = r.number(data, "road_width", lo=2.0, hi=30.0)
    lanes = data.get("lanes", 1)
    if lanes not in (1, 2) or isinstance(lanes, bool):
        r.fail(f"'lanes' must be 1 or 2, got {lanes!r}")
    shoulder = r.number(data, "shoulder_width", 1.0, lo=0.0, hi=10.0)
    control = _control_points(data["centerline"], r)

    pts, tan, curv, length = resample_loop(control)
    s = np.arange(len(pts)) * (length / len(pts))
    normals = np.stack([-tan[:, 1], tan[:, 0]], 1)
    need = max(MIN_TURN_RADIUS, road_width / 2 + shoulder + 1.0)
    k = int(np.argmax(np.abs(curv)))
    if 1.0 / max(abs(curv[k]), 1e-12) < need:
        r.fail(f"curve radius {1 / abs(curv[k]):.1f} m at s={s[k]:.0f} m (near x={pts[k, 0]:.1f}, "
               f"y={pts[k, 1]:.1f}) is below the {need:.1f} m this road width and shoulder need")
    _check_overlap(pts, s, length, road_width + 2 * shoulder, r)

    kinds = V1_SURFACE_KINDS if version == 1 else SURFACE_KINDS
    surfaces = tuple(_surface(item, i, length, r, kinds) for i, item in enumerate(r.list(data, "surfaces")))
    scenery = _scenery(r.obj(data, "scenery"), r, V1_THEMES if version == 1 else THEMES)
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
        source=source, description=str(data.get("description", "")), digest=digest, version=int(version),
        edges=parse_edges(r.obj(data, "edges"), r), sky=parse_sky(r.obj(data, "sky"), r),
        appearance=parse_appearance(r.obj(data, "appearance"), r),
    )


def _control_points(raw: object, r: Reader) -> np.ndarray:
    if not isinstance(raw, list):
        r.fail("'centerline' must be a list of [x, y] points")
    if len(raw) > MAX_CONTROL_POINTS:  # the spline solve is O(n^2) in memory: refuse before allocating
        r.fail(f"centerline has {len(raw)} points; at most {MAX_CONTROL_POINTS} control points are accepted "
               "(the spline through them is resampled every 0.5 m anyway)")
    for i, p in enumerate(raw):
        if (not isinstance(p, list | tuple) or len(p) != 2
                or not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in p)):
            r.fail(f"centerline point {i} must be [x, y] with finite numbers, got {p!r}")
        if max(abs(p[0]), abs(p[1])) > MAX_COORDINATE_M:
            r.fail(f"centerline point {i} {p!r} is more than {MAX_COORDINATE_M:g} m from the origin")
    pts = np.asarray(raw, dtype=np.float64).reshape(-1, 2)
    if len(pts) >= 2 and np.allclose(pts[0], pts[-1]):
        log.debug("%s: last centre-line point repeats the first; dropping it", r.source)
        pts = pts[:-1]
    if len(pts) < 4:
        r.fail(f"centerline needs at least 4 points for a closed loop, got {len(pts)}")
    step = np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)
    if step.sum() > MAX_LENGTH_M:
        r.fail(f"the loop through the centre-line points is {step.sum() / 1000:.1f} km long; "
               f"at most {MAX_LENGTH_M / 1000:g} km is accepted")
    if step.min() < 1e-3:
        i = int(np.argmin(step))
        r.fail(f"centerline points {i} and {(i + 1) % len(pts)} coincide")
    return pts


def _check_overlap(pts: np.ndarray, s: np.ndarray, length: float, clearance: float, r: Reader) -> None:
    """Fail when two stretches of road (shoulders included) overlap or the centre line crosses itself
    (the rule: :func:`tools.sim.track.geometry.closest_overlap`, checked on a ~1 m grid)."""
    step = max(1, int(round(1.0 / (length / len(pts)))))
    p, ss = pts[::step], s[::step]
    hit = closest_overlap(p, ss, length, clearance)
    if hit is not None:
        i, j, d = hit
        what = "crosses itself" if d < 0.5 else "overlaps itself"
        r.fail(f"road {what} near s={ss[i]:.0f} m and s={ss[j]:.0f} m (x={p[i, 0]:.1f}, y={p[i, 1]:.1f}): "
               f"centre lines {d:.1f} m apart, road plus shoulders need {clearance:.1f} m")


def _surface(item: object, i: int, length: float, r: Reader, kinds: tuple[str, ...]) -> Surface:
    if not isinstance(item, dict):
        r.fail(f"surfaces[{i}] must be an object with from_s, to_s, kind")
    r.keys(item, f"surfaces[{i}]", {"from_s", "to_s", "kind"})
    kind = item.get("kind", "asphalt")
    if kind not in kinds:
        more = " (needs version 2)" if kind in SURFACE_KINDS else ""
        r.fail(f"surfaces[{i}]: unknown surface kind {kind!r}{more} (known: {', '.join(kinds)})")
    a = r.number(item, "from_s", lo=0.0, where=f"surfaces[{i}]")
    b = r.number(item, "to_s", lo=0.0, where=f"surfaces[{i}]")
    if a > length + 1e-6 or b > length + 1e-6:
        r.fail(f"surfaces[{i}]: from_s/to_s must lie within the track length {length:.1f} m")
    if a == b:
        r.fail(f"surfaces[{i}]: from_s equals to_s (empty stretch)")
    return Surface(a, b, kind)


def _scenery(raw: dict, r: Reader, themes: tuple[str, ...]) -> Scenery:
    r.keys(raw, "scenery", {"theme", "trees", "poles", "water", "kerbs"})
    theme = raw.get("theme", "meadow")
    if theme not in themes:
        more = " (needs version 2)" if theme in THEMES else ""
        r.fail(f"scenery.theme: unknown theme {theme!r}{more} (known: {', '.join(themes)})")
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


@lru_cache(maxsize=16)
def _load_track(name: str, mtime: float) -> Track:
    return load_track(name)


def get_track(name: str) -> Track:
    """Load a track once per process (tracks are immutable); a changed file is re-read."""
    path = Path(name)
    return _load_track(name, path.stat().st_mtime if path.is_file() else 0.0)
