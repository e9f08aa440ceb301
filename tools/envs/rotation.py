"""Which world each episode of ``rbc/Drive-v0`` drives: the rotating pool of a :class:`WorldDistribution`.

Kept apart from the environment because its draws must not depend on what the episodes do: the pool's worlds and
each episode's pick come from streams of their own (seeded from ``reset(seed=...)``, apart from the episode's
``np_random``), and a prefetch only builds early what a later reset would draw anyway. So the same seed gives the
same worlds whether or not the background builds were done in time.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from tools.envs.client import Episode
from tools.envs.worldcache import WorldCache, WorldKey

if TYPE_CHECKING:
    from tools.envs.config import DriveEnvConfig

#: the distribution's stream of worlds, apart from the episode's own draws (np_random)
WORLD_STREAM = 0x3D1


class WorldRotation:
    """The distribution's worlds in play (``pool``, oldest first) and its two streams: the worlds that enter the
    pool and each episode's pick; without a distribution only the worlds that reset options pin."""

    def __init__(self, config: DriveEnvConfig, cache: WorldCache) -> None:
        self.config = config
        self.cache = cache
        self._world_rng: np.random.Generator | None = None
        self._pick_rng: np.random.Generator | None = None
        self.next_world: tuple[str, float] | None = None  # drawn for the next new-world reset (being prefetched)
        self.since_new = 0  # steps since the newest world of the pool entered it
        self.pool: list[tuple[str, float]] = []  # the distribution's worlds (and suns) in play, oldest first

    def draw(self, seed: int | None, pinned: dict[str, Any], np_random: np.random.Generator) -> Episode | None:
        """This episode's world: pinned by the options, drawn from the distribution's pool or None (the env's own
        track, built as ``rbc sim`` builds it)."""
        dist = self.config.worlds
        if dist is not None and (seed is not None or self._world_rng is None):
            # the worlds' own streams: the same worlds for a seed, whatever the episodes did with np_random
            entropy = seed if seed is not None else int(np_random.integers(2**62))
            self._world_rng = np.random.default_rng([entropy, WORLD_STREAM, 0])
            self._pick_rng = np.random.default_rng([entropy, WORLD_STREAM, 1])
            self.since_new, self.next_world = 0, None
            self.pool = [dist.draw_world(self._world_rng) for _ in range(dist.pool)]
        track, sun = pinned.get("track"), pinned.get("sun_deg")
        if track is None and dist is not None:
            assert self._world_rng is not None and self._pick_rng is not None  # seeded above
            if self.since_new >= dist.new_world_steps:  # a new world, driven at once
                self.pool = [*self.pool[1:], self.next_world or dist.draw_world(self._world_rng)]
                self.next_world, self.since_new = None, 0
                track, drawn_sun = self.pool[-1]
            else:
                track, drawn_sun = self.pool[int(self._pick_rng.integers(len(self.pool)))]
            sun = drawn_sun if sun is None else sun
        elif track is None:
            if not {"sun_deg", "light_intensity", "fog"} & set(pinned):
                return None
            track = self.config.track_name
        key = self.key(track, sun or 0.0, pinned.get("themes"), int(pinned.get("cone_seed", 0)))
        return Episode(key, self.cache.get(key), pinned.get("light_intensity", self.config.light_intensity),
                       pinned.get("fog", 1.0))

    def key(self, track: str, sun: float, themes: tuple[str, ...] | None = None, cone_seed: int = 0) -> WorldKey:
        """The cache's key of a world: the distribution's themes for a generated one unless pinned."""
        from tools.sim.track.files import world_seed_of

        if themes is None and self.config.worlds is not None:
            themes = self.config.worlds.themes
        return WorldKey(track, themes if world_seed_of(track) is not None else None, float(sun), self.config.cones,
                        cone_seed)

    def stepped(self) -> None:
        """Count a step; halfway to ``new_world_steps``, start building the next new world in the background."""
        dist = self.config.worlds
        if dist is None:
            return
        self.since_new += 1
        if dist.prefetch and self.next_world is None and 2 * self.since_new >= dist.new_world_steps:
            self.prefetch()

    def prefetch(self) -> None:
        """Build in the background the pool's worlds not built yet and, from halfway to ``new_world_steps``, the
        world the next new-world reset brings into the pool (drawn now: the draws stay those of resets)."""
        dist, rng = self.config.worlds, self._world_rng
        if dist is None or not dist.prefetch or rng is None:
            return
        for track, sun in self.pool:
            self.cache.prefetch(self.key(track, sun))
        if 2 * self.since_new >= dist.new_world_steps:
            if self.next_world is None:
                self.next_world = dist.draw_world(rng)
            self.cache.prefetch(self.key(*self.next_world))
