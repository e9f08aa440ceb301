"""The built worlds of ``rbc/Drive-v0``: each world's textures, built once per process and kept in an LRU.

A world's textures take about a second of CPU to build (and a new world's track file about a second to generate,
once per machine), as long as hundreds of steps. So the episodes drive a rotating pool of built worlds (drawn by
:class:`tools.envs.worlds.WorldDistribution`), a new one entering every few episodes, and :class:`WorldCache`
(one per process, an LRU keyed by :class:`WorldKey`: the world, its themes, the sun and the cones) builds the next
one in a background thread while the episode before runs. What is drawn depends only on the seeds, never on
timing: timing changes when a world is built, not which.
"""

from __future__ import annotations

import copy
import os
import tempfile
import threading
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tools.sim.render.world import World
    from tools.sim.track.road import Track

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
        built = BuiltWorld(path, World(track, key.sun_deg, cones, keep_albedo=bool(key.cones)))
        if not key.cones:  # the build let the albedo go (see release_albedo)
            _trim_heap()
        return built


def release_albedo(track: Track, trim: bool = False) -> None:
    """Drop the ground albedo the renderer cached while building ``track``'s world (128 MB for the lake; the built
    world keeps only its lit texture), and give the heap back (``trim``: also where the build let it go itself,
    ``keep_albedo=False``). Done after every world built without cones: with cones each layout is a world of its
    own, painted on the same albedo, so it stays; another sun for a track paints it again (about a second, once
    per world built)."""
    from tools.sim.render.world import forget_albedo

    with _BUILD_LOCK:
        if forget_albedo(track) or trim:
            _trim_heap()


def _trim_heap() -> None:
    """Give the C heap's free memory back to the system (:func:`tools.sim.render.world.trim_heap`): a world's build
    frees hundreds of MB of temporaries below glibc's raised mmap threshold, which stay in the process."""
    from tools.sim.render.world import trim_heap

    trim_heap()


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
