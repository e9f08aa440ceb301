"""What the world generator may produce, and which seeds are reserved for what (data, not code)."""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from pathlib import Path

from protocol.errors import BadValue
from tools.sim.track.road import MIN_TURN_RADIUS, THEMES
from tools.sim.track.themes import GENERIC_THEMES

#: Seed ranges, half-open [start, stop). Training and evaluation worlds never share a seed, so a
#: model is never evaluated on a world it was trained on; ``dev`` is for trying things out.
SEED_RANGES: dict[str, range] = {
    "train": range(0, 1_000_000),
    "eval": range(1_000_000, 2_000_000),
    "dev": range(2_000_000, 3_000_000),
}

#: Bumped whenever the same seed would give a different world (worlds record it in their description).
GENERATOR_VERSION = 1


def world_seed_range(name: str) -> range:
    """The seeds reserved for ``name`` ("train", "eval" or "dev")."""
    try:
        return SEED_RANGES[name]
    except KeyError:
        raise BadValue(f"unknown seed range {name!r} (known: {', '.join(SEED_RANGES)})") from None


def seed_range_of(seed: int) -> str | None:
    """Which reserved range ``seed`` belongs to, or None when it is in none of them."""
    return next((name for name, r in SEED_RANGES.items() if seed in r), None)


@dataclass(frozen=True)
class WorldGenConfig:
    """Bounds of the generated worlds. The defaults are the distribution documented in the README."""

    min_length_m: float = 500.0
    max_length_m: float = 1500.0
    # Tightest hairpin. The car turns on 5.8 m at full lock and the kinematic car's autopilot drives 8 m
    # hairpins, but the dynamic car runs wide out of them (1 lap in 20 needed a take-over at 8-9 m)
    min_radius_m: float = 10.0
    narrow_radius_m_per_m: float = 1.5  # hairpins of roads narrower than two_lane_min_width_m: this much wider
    min_road_width_m: float = 5.0
    max_road_width_m: float = 10.0
    two_lane_min_width_m: float = 6.5  # two lanes of at least 3.25 m
    # centre lines of stretches that are not neighbours along the road stay this far beyond road + shoulders
    clearance_margin_m: float = 3.0
    max_attempts: int = 200  # layouts tried per candidate world before giving up (rejected deterministically)
    # Candidate worlds are driven by the autopilot (both cars, 30 km/h, no rendering) and rejected
    # unless both lap at eta 100 %; False skips it (the same world whenever the first candidate passes).
    drive_check: bool = True
    max_candidates: int = 8
    themes: tuple[str, ...] = GENERIC_THEMES  # the Udacity-like themes only when asked for (--world-config)
    randomise_appearance: bool = True  # False: the theme's own palette and a plain camera image

    def __post_init__(self) -> None:
        if not 0 < self.min_length_m < self.max_length_m:
            raise BadValue("need 0 < min_length_m < max_length_m")
        if self.min_radius_m < MIN_TURN_RADIUS:
            raise BadValue(f"min_radius_m must be at least the simulator's {MIN_TURN_RADIUS} m")
        if not 2.0 <= self.min_road_width_m <= self.max_road_width_m <= 30.0:
            raise BadValue("need 2 <= min_road_width_m <= max_road_width_m <= 30")
        unknown = set(self.themes) - set(THEMES)
        if not self.themes or unknown:
            raise BadValue(f"themes must be a non-empty subset of {', '.join(THEMES)}")


def seed_label(seed: int) -> str:
    """``"eval range 1,000,000-1,999,999"``, or a warning that the seed is in no reserved range."""
    name = seed_range_of(seed)
    if name is None:
        return "in no reserved range"
    r = SEED_RANGES[name]
    return f"{name} range {r.start:,}-{r.stop - 1:,}"


def parse_world_config(text: str) -> WorldGenConfig:
    """A :class:`WorldGenConfig` from a JSON object of its fields (inline, or a file holding one)."""
    source = Path(text).read_text(encoding="utf-8") if not text.lstrip().startswith("{") else text
    try:
        values = json.loads(source)
    except json.JSONDecodeError as exc:
        raise BadValue(f"world config is not JSON: {exc}") from None
    known = {f.name for f in fields(WorldGenConfig)}
    if not isinstance(values, dict) or set(values) - known:
        unknown = sorted(set(values) - known) if isinstance(values, dict) else []
        raise BadValue(f"world config must be a JSON object of WorldGenConfig fields ({', '.join(sorted(known))})"
                         + (f"; unknown: {', '.join(unknown)}" if unknown else ""))
    try:
        if "themes" in values:
            values["themes"] = tuple(values["themes"])
        return WorldGenConfig(**values)
    except TypeError as exc:
        raise BadValue(f"world config: {exc}") from None
