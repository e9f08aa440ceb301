"""``generate_world(seed)``: one procedural world as a version-2 track document, validated before it is returned.

Two generators per seed: one for the road's layout, one for everything on and around it, so a change
to how worlds are dressed never moves a road. Every document is loaded back with the simulator's
own loader and checked (:func:`check_world`) before it is returned: a seed gives a valid world or
an error, never a file that fails later.
"""

from __future__ import annotations

import json
import logging
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from protocol.errors import BadValue
from tools.sim.track.files import FORMAT_VERSION, parse_track, world_seed_of, write_track_file
from tools.sim.track.road import Track, TrackError
from tools.sim.worldgen import dress
from tools.sim.worldgen.config import GENERATOR_VERSION, WorldGenConfig, seed_range_of
from tools.sim.worldgen.layout import CONTROL_SPACING_M, DS, make_layout, too_close

log = logging.getLogger(__name__)

DEFAULT_CONFIG = WorldGenConfig()


def generate_world(seed: int, config: WorldGenConfig = DEFAULT_CONFIG) -> dict:
    """The track document (JSON-ready dict) of world ``seed``; identical for identical arguments.

    Candidate worlds are drawn from streams seeded by (seed, candidate number) until one passes
    :func:`check_world` and (``config.drive_check``) the autopilot's lap with both cars.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise BadValue(f"a world seed is an integer >= 0, got {seed!r}")
    seed = int(seed)
    for candidate in range(config.max_candidates):
        doc = _candidate(seed, candidate, config)
        problems = check_world(doc, config)
        if problems:  # a generator bug, not bad luck: rejection happens in make_layout
            raise RuntimeError(f"world {seed} failed its checks: {'; '.join(problems)}")
        if not config.drive_check or _drives(doc):
            return doc
        log.debug("world %d: candidate %d needs a take-over by the autopilot; drawing another", seed, candidate)
    raise RuntimeError(f"world {seed}: no candidate of {config.max_candidates} drivable by the autopilot")


def _drives(doc: dict) -> bool:
    """Whether the autopilot laps the world at eta 100 % with both cars (a temporary track file)."""
    from tools.sim.worldgen.drive_check import drive_check  # the simulator, only when asked for

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "world.json"
        path.write_text(json.dumps(doc), encoding="utf-8")
        return all(drive_check(path, v).ok for v in ("dynamic", "kinematic"))


def _candidate(seed: int, candidate: int, config: WorldGenConfig) -> dict:
    road = np.random.default_rng([seed, GENERATOR_VERSION, 1, candidate])
    width = round(float(road.uniform(config.min_road_width_m, config.max_road_width_m)), 2)
    lanes = 2 if width >= config.two_lane_min_width_m and road.uniform() < 0.5 else 1
    shoulder = round(float(road.uniform(0.5, 2.0)), 2)
    lay = make_layout(road, config, width, shoulder)
    length = len(lay.points) * DS

    rng = np.random.default_rng([seed, GENERATOR_VERSION, 2, candidate])
    theme = str(rng.choice(config.themes))
    edge = width / 2 + shoulder
    surfaces = dress.surfaces(rng, length, theme)
    ponds, bridges = dress.water(rng, lay, theme, keep_off=edge + 3.0, half_deck=width / 2 + 0.7)
    scenery = dress.scenery(rng, theme, length, edge)
    scenery["water"] = ponds
    elevation = 8.0 + 67.0 * float(rng.uniform()) ** 1.2
    sun = {"azimuth_deg": round(float(rng.uniform(0, 360)), 1), "elevation_deg": round(elevation, 1)}
    bumpy = rng.uniform() < 0.5
    jitter = {"pitch_deg": round(float(rng.uniform(0, 0.8)), 2) if bumpy else 0.0,
              "roll_deg": round(float(rng.uniform(0, 0.6)), 2) if bumpy else 0.0}
    edges, sky = dress.edges(rng, theme), dress.sky(rng, theme)
    look = dress.appearance(rng, theme) if config.randomise_appearance else {}
    step = int(round(CONTROL_SPACING_M / DS))
    where = seed_range_of(seed) or "no reserved range"
    kinds = sorted({s["kind"] for s in surfaces} | ({"asphalt"} if not surfaces or surfaces[0]["to_s"] < length - 1
                                                     else set()) | {b["kind"] for b in bridges})
    doc = {
        "name": f"world-{seed}", "version": FORMAT_VERSION,
        "description": (f"procedural world {seed} ({where}; generator {GENERATOR_VERSION}): {length / 1000:.2f} km, "
                        f"{theme}, {lanes} lane(s) {width:.1f} m, {', '.join(kinds)}; "
                        + ", ".join(f"{v} {k}" for k, v in lay.features.items())),
        "centerline": np.round(lay.points[::step], 3).tolist(),
        "road_width": width, "lanes": lanes, "shoulder_width": shoulder,
        "surfaces": surfaces + bridges, "scenery": scenery, "sun": sun, "start": {"s": round(lay.start_s, 1)},
        "camera_jitter": jitter, "edges": edges, "sky": sky, "appearance": look,
    }
    return doc


@dataclass(frozen=True)
class WorldFacts:
    length_m: float
    min_radius_m: float
    clearance_m: float


def world_facts(track: Track, config: WorldGenConfig = DEFAULT_CONFIG) -> WorldFacts:
    return WorldFacts(track.length, track.min_radius,
                      track.road_width + 2 * track.shoulder_width + config.clearance_margin_m)


def check_world(doc: dict, config: WorldGenConfig = DEFAULT_CONFIG) -> list[str]:
    """What is wrong with a generated document (empty: nothing): it loads, keeps clear of itself,
    respects the radius and length bounds."""
    try:
        track = parse_track(doc, doc.get("name", "<world>"))
    except ValueError as exc:
        return [str(exc)]
    f = world_facts(track, config)
    out = []
    if f.min_radius_m < config.min_radius_m:
        out.append(f"curve radius {f.min_radius_m:.1f} m below {config.min_radius_m:g} m")
    if not config.min_length_m <= f.length_m <= config.max_length_m:
        out.append(f"length {f.length_m:.0f} m outside {config.min_length_m:g}-{config.max_length_m:g} m")
    if too_close(track.centerline, f.clearance_m):
        out.append(f"comes within {f.clearance_m:.1f} m of itself")
    return out


def write_world(seed: int, path: str | Path, config: WorldGenConfig = DEFAULT_CONFIG) -> Path:
    """Write world ``seed`` as a track file (loads with ``load_track``, ``rbc sim --track PATH``)."""
    return write_track_file(path, generate_world(seed, config))


def resolve_track_name(track: str) -> str:
    """A ``--track`` value as the simulator loads it: ``world:SEED`` becomes the path of that world's file.

    The world is written (once per generator version; temp file, then rename) to ``rbc-worlds/`` in the
    system's temp folder, so every worker process of a command loads the same file. Other names and
    paths are returned unchanged. A malformed ``world:`` name raises :class:`TrackError`.
    """
    seed = world_seed_of(track)
    if seed is None:
        return track
    path = Path(tempfile.gettempdir()) / "rbc-worlds" / f"world-{seed}-g{GENERATOR_VERSION}.json"
    if not path.is_file():
        try:
            write_world(seed, path)
        except (ValueError, RuntimeError) as exc:
            raise TrackError(f"{track}: {exc}") from None
    return str(path)


def write_worlds(seeds: list[int], folder: str | Path, config: WorldGenConfig = DEFAULT_CONFIG) -> list[Path]:
    """One track file per seed, ``folder/world-SEED.json``."""
    return [write_world(s, Path(folder) / f"world-{s}.json", config) for s in seeds]
