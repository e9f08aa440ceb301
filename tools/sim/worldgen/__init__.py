"""Procedural worlds: closed roads with varied geometry, surfaces, edges, scenery, sky and camera look.

``generate_world(seed) -> dict`` is a version-2 track document; ``write_world(seed, path)`` writes it
as a track file any simulator command loads. Seeds are reserved per purpose (:data:`SEED_RANGES`):
``world_seed_range("train")`` and ``world_seed_range("eval")`` never overlap.

May import: ``tools.sim.track``, ``.render``, ``.driving`` (a candidate is driven before it is kept)
and ``.pictures`` (the contact sheet).
"""

from tools.sim.worldgen.config import (
    GENERATOR_VERSION,
    SEED_RANGES,
    WorldGenConfig,
    seed_range_of,
    world_seed_range,
)
from tools.sim.worldgen.generate import check_world, generate_world, resolve_track_name, write_world, write_worlds

__all__ = ["GENERATOR_VERSION", "SEED_RANGES", "WorldGenConfig", "check_world", "generate_world",
           "resolve_track_name", "seed_range_of", "world_seed_range", "write_world", "write_worlds"]
