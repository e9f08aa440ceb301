"""Domain randomisation for ``rbc/Drive-v0``: what :meth:`DriveEnv.reset` draws per episode, and the built worlds.

:class:`WorldDistribution` is the declared distribution (``gymnasium.make("rbc/Drive-v0", worlds={...})``): a
generated world from a range of TRAINING seeds (or a built-in track), its themes, the sun's height, the light's
intensity and the fog. Seeds outside the training range (the held-out evaluation worlds) are refused when the
distribution is declared, so they are never drawn.

A world's textures take about a second of CPU to build (and a new world's track file about a second to generate,
once per machine), as long as hundreds of steps. So the episodes drive a rotating pool of built worlds, a new one
entering every few episodes, and :class:`WorldCache` (one per process, an LRU keyed by :class:`WorldKey`: the
world, its themes, the sun and the cones) builds the next one in a background thread while the episode before
runs. What is drawn depends only on the seeds, never on timing: timing changes when a world is built, not which.
"""

from __future__ import annotations

import copy
import math
import os
import tempfile
import threading
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from protocol.errors import BadValue

if TYPE_CHECKING:
    from tools.sim.render.world import World

#: one build at a time in a process: the renderer's own albedo and prop caches are not thread-safe
_BUILD_LOCK = threading.Lock()


def _after_fork_in_child() -> None:
    """A forked child has none of the parent's threads: fresh locks (a build may have held one) and no
    background builds (their futures would never finish there); the worlds built stay."""
    global _BUILD_LOCK
    _BUILD_LOCK = threading.Lock()
    _SHARED._lock = threading.RLock()
    _SHARED._pool = None
    _SHARED._pending.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


@dataclass(frozen=True)
class WorldDistribution:
    """What ``reset()`` draws per episode (``gymnasium.make("rbc/Drive-v0", worlds=WorldDistribution(...))`` or
    ``worlds={...}`` of these fields, as an rl-zoo ``env_kwargs`` can).

    Worlds: ``seeds``, generated worlds ``first..last`` (inclusive, training seeds only), and the built-in
    ``tracks``, drawn uniformly; ``themes``, the generator's themes a world may have (None: its seven generic
    ones; a world is its seed AND its themes); ``sun_deg``, the sun raised (+) or lowered by one of these
    angles. A world's textures take one to two seconds of CPU to build, as long as a thousand steps, so the
    episodes drive a rotating ``pool`` of built worlds: each episode one of them, and at the first reset after
    ``new_world_steps`` steps a newly drawn world replaces the oldest (and is the one driven; ``prefetch``:
    built in the background during the steps before). The building then costs a bounded share of the steps,
    whatever the episodes' lengths; ``pool=1, new_world_steps=1`` is a new world every episode. Each episode:
    ``light``, the light intensity, log-uniform in ``[lo, hi]`` (None: the env's ``light_intensity``);
    ``fog``, the world's fog density times a factor log-uniform in ``[lo, hi]`` (None: its own); the spawn
    with ``spawn="random"``.
    """

    seeds: tuple[int, int] | None = (0, 999)
    tracks: tuple[str, ...] = ()
    themes: tuple[str, ...] | None = None
    sun_deg: tuple[float, ...] = (0.0,)
    light: tuple[float, float] | None = (0.4, 2.5)
    fog: tuple[float, float] | None = (0.5, 2.0)
    pool: int = 4
    new_world_steps: int = 20_000
    prefetch: bool = True

    def __post_init__(self) -> None:
        from tools.sim.collect.worlds import training_seed_problem
        from tools.sim.track.files import builtin_tracks
        from tools.sim.track.road import THEMES

        seeds = _pair("worlds seeds", self.seeds, int) if self.seeds is not None else None
        if seeds is not None:
            first, last = seeds
            if first < 0 or last < first:
                raise BadValue(f"worlds seeds must be (first, last) with 0 <= first <= last, got {self.seeds!r}")
            problem = training_seed_problem(first, last - first + 1)
            if problem:
                raise BadValue(f"worlds: {problem}", "the distribution draws training worlds only; evaluate "
                                                    "on held-out worlds with world_seed=S, purpose='eval'")
        object.__setattr__(self, "seeds", seeds)
        tracks = _strings("worlds tracks", self.tracks)
        known = builtin_tracks()
        for name in tracks:
            if name not in known:
                raise BadValue(f"worlds tracks must be built-in track names ({', '.join(known)}), got {name!r}",
                               "draw generated worlds with seeds=(first, last)")
        object.__setattr__(self, "tracks", tracks)
        if seeds is None and not tracks:
            raise BadValue("worlds must draw from seeds=(first, last), tracks=(...) or both, got neither")
        if self.themes is not None:
            themes = _strings("worlds themes", self.themes)
            unknown = [t for t in themes if t not in THEMES]
            if not themes or unknown:
                raise BadValue(f"worlds themes must be a non-empty list of {', '.join(THEMES)}, got {self.themes!r}")
            object.__setattr__(self, "themes", tuple(sorted(set(themes))))
        sun = self.sun_deg if isinstance(self.sun_deg, list | tuple) else [self.sun_deg]
        if not sun or not all(_finite(a) and -90.0 <= float(a) <= 90.0 for a in sun):
            raise BadValue(f"worlds sun_deg must be angles in [-90, 90] degrees, got {self.sun_deg!r}")
        object.__setattr__(self, "sun_deg", tuple(float(a) for a in sun))
        for name in ("light", "fog"):
            value = getattr(self, name)
            if value is not None:
                lo, hi = _pair(f"worlds {name}", value, float)
                if not 0 < lo <= hi < math.inf:
                    raise BadValue(f"worlds {name} must be (lo, hi) with 0 < lo <= hi, got {value!r}")
                object.__setattr__(self, name, (float(lo), float(hi)))
        for name, low in (("pool", 1), ("new_world_steps", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise BadValue(f"worlds {name} must be an integer >= {low}, got {value!r}")
        if not isinstance(self.prefetch, bool):
            raise BadValue(f"worlds prefetch must be true or false, got {self.prefetch!r}")

    @classmethod
    def of(cls, value: object) -> WorldDistribution | None:
        """A WorldDistribution from itself, a mapping of its fields, True (the defaults) or None/False (off)."""
        if value is None or value is False:
            return None
        if value is True:
            return cls()
        if isinstance(value, cls):
            return value
        if not isinstance(value, dict):
            raise BadValue(f"worlds must be a tools.envs.WorldDistribution or a dict of its fields, got {value!r}")
        known = [f.name for f in fields(cls)]
        unknown = sorted(map(str, set(value) - set(known)))
        if unknown:
            raise BadValue(f"unknown worlds option(s): {', '.join(unknown)}", f"known: {', '.join(known)}")
        return cls(**value)

    def draw_world(self, rng: np.random.Generator) -> tuple[str, float]:
        """(the track name, ``world:SEED`` or a built-in name, and the sun's angle) of the next world."""
        count = 0 if self.seeds is None else self.seeds[1] - self.seeds[0] + 1
        pick = int(rng.integers(count + len(self.tracks)))
        name = f"world:{self.seeds[0] + pick}" if pick < count and self.seeds is not None \
            else self.tracks[pick - count]
        sun = self.sun_deg[int(rng.integers(len(self.sun_deg)))] if len(self.sun_deg) > 1 else self.sun_deg[0]
        return name, sun

    def draw_light(self, rng: np.random.Generator, default: float) -> float:
        return default if self.light is None else _log_uniform(rng, self.light)

    def draw_fog(self, rng: np.random.Generator) -> float:
        return 1.0 if self.fog is None else _log_uniform(rng, self.fog)


def _log_uniform(rng: np.random.Generator, bounds: tuple[float, float]) -> float:
    lo, hi = bounds
    return round(float(math.exp(math.log(lo) + rng.uniform() * (math.log(hi) - math.log(lo)))), 4)


def _finite(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _pair(name: str, value: object, kind: type) -> tuple[Any, Any]:
    items: list[Any] = list(value) if isinstance(value, list | tuple) else []
    ok = len(items) == 2 and all(_finite(v) for v in items)
    if ok and kind is int:
        ok = all(float(v).is_integer() for v in items)
    if not ok:
        raise BadValue(f"{name} must be two {'integers' if kind is int else 'numbers'} (lo, hi), got {value!r}")
    return kind(items[0]), kind(items[1])


def _strings(name: str, value: object) -> tuple[str, ...]:
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list | tuple) or not all(isinstance(v, str) for v in items):
        raise BadValue(f"{name} must be a list of names, got {value!r}")
    return tuple(items)


# --------------------------------------------------------------------------------------------- built worlds

@dataclass(frozen=True)
class WorldKey:
    """What a built world depends on: the track (``world:SEED`` or a name/path), the generator's themes for a
    generated one (None: its default), the sun's angle and the cones (count and layout seed)."""

    track: str
    themes: tuple[str, ...] | None = None
    sun_deg: float = 0.0
    cones: int = 0
    cone_seed: int = 0


@dataclass(frozen=True)
class BuiltWorld:
    path: str  # the track file or name the simulator loads
    world: World


def track_path(track: str, themes: tuple[str, ...] | None = None) -> str:
    """The file a track name loads from: ``world:SEED`` generated once per machine (``rbc sim``'s file for the
    default themes; for others a file of its own beside it), names and paths as they are."""
    from tools.sim.track.files import world_seed_of, write_track_file
    from tools.sim.track.road import TrackError
    from tools.sim.worldgen import GENERATOR_VERSION, WorldGenConfig, generate_world, resolve_track_name

    seed = world_seed_of(track)
    if seed is None or themes is None:
        return resolve_track_name(track)
    path = Path(tempfile.gettempdir()) / "rbc-worlds" / f"world-{seed}-g{GENERATOR_VERSION}-{'-'.join(themes)}.json"
    if not path.is_file():
        try:
            write_track_file(path, generate_world(seed, WorldGenConfig(themes=themes)))
        except (ValueError, RuntimeError) as exc:
            raise TrackError(f"{track}: {exc}") from None
    return str(path)


def build_world(key: WorldKey) -> BuiltWorld:
    """Generate (once per machine) and load the track, and build its world's textures for the sun and cones."""
    from tools.sim.render.world import World
    from tools.sim.track.cones import place_cones
    from tools.sim.track.files import get_track

    path = track_path(key.track, key.themes)
    with _BUILD_LOCK:
        track = get_track(path)
        cones = place_cones(track, key.cones, key.cone_seed) if key.cones else None
        return BuiltWorld(path, World(track, key.sun_deg, cones))


def with_fog(world: World, factor: float) -> World:
    """The same world seen through ``factor`` times its fog (a view sharing its textures; the renderer reads the
    density from the track's appearance)."""
    if factor == 1.0:
        return world
    view = copy.copy(world)
    look = world.track.appearance
    view.track = replace(world.track, appearance=replace(look, haze=look.haze * factor))
    return view


class WorldCache:
    """The last ``size`` built worlds (LRU by :class:`WorldKey`) and those being built in the background.

    One per process (:func:`shared_cache`): the environments of a ``SyncVectorEnv`` share their worlds, and the
    workers a ``fork``-started ``AsyncVectorEnv`` starts inherit the worlds built before (read-only textures
    stay shared pages). Safe to use from several threads.
    """

    def __init__(self, size: int = 2) -> None:
        self.size = size
        self._built: OrderedDict[WorldKey, BuiltWorld] = OrderedDict()
        self._pending: dict[WorldKey, Future[BuiltWorld]] = {}
        self._pool: ThreadPoolExecutor | None = None
        self._lock = threading.RLock()
        self.builds = 0  # worlds built (in either thread)
        self.waits = 0  # gets that found their world still being built in the background

    def get(self, key: WorldKey) -> BuiltWorld:
        """The built world of ``key``: from the cache, from the background build (waiting for it) or built now."""
        with self._lock:
            if key in self._built:
                self._built.move_to_end(key)
                return self._built[key]
            future = self._pending.pop(key, None)
        if future is not None:
            self.waits += not future.done()
            built = future.result()
        else:
            built = self._build_counted(key)
        with self._lock:
            self._keep(key, built)
        return built

    def _keep(self, key: WorldKey, built: BuiltWorld) -> None:
        self._built[key] = built
        self._built.move_to_end(key)
        while len(self._built) > self.size:
            self._built.popitem(last=False)

    def prefetch(self, key: WorldKey) -> None:
        """Start building ``key``'s world in the background unless it is built or being built."""
        with self._lock:
            for done in [k for k, f in self._pending.items() if f.done()]:  # finished builds join the cache
                future = self._pending.pop(done)
                if future.exception() is None:
                    self._keep(done, future.result())
            if key in self._built or key in self._pending:
                return
            if self._pool is None:
                self._pool = ThreadPoolExecutor(1, thread_name_prefix="rbc-world")
            self._pending[key] = self._pool.submit(self._build_counted, key)

    def wait(self) -> None:
        """Until every background build has finished (benchmarks: nothing runs behind the clock)."""
        with self._lock:
            pending = list(self._pending.values())
        for future in pending:
            future.exception()

    def _build_counted(self, key: WorldKey) -> BuiltWorld:
        built = build_world(key)
        with self._lock:
            self.builds += 1
        return built

    def clear(self) -> None:
        """Forget every built world (their memory goes back); a build under way finishes in its thread."""
        with self._lock:
            self._pending.clear()
            self._built.clear()


_SHARED = WorldCache(1)


def shared_cache(size: int) -> WorldCache:
    """The process's world cache, holding at least ``size`` worlds from now on."""
    _SHARED.size = max(_SHARED.size, size)
    return _SHARED
