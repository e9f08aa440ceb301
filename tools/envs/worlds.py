"""Domain randomisation for ``rbc/Drive-v0``: what :meth:`DriveEnv.reset` draws per episode.

:class:`WorldDistribution` is the declared distribution (``gymnasium.make("rbc/Drive-v0", worlds={...})``): a
generated world from a range of TRAINING seeds (or a built-in track), its themes, the sun's height, the light's
intensity and the fog. Seeds outside the training range (the held-out evaluation worlds) are refused when the
distribution is declared, so they are never drawn. The worlds drawn are built, cached and prefetched by
:mod:`tools.envs.worldcache`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import overload

import numpy as np

from protocol.errors import BadValue


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


@overload
def _pair(name: str, value: object, kind: type[int]) -> tuple[int, int]: ...
@overload
def _pair(name: str, value: object, kind: type[float]) -> tuple[float, float]: ...
def _pair(name: str, value: object, kind: type[int] | type[float]) -> tuple[float, float]:
    items = list(value) if isinstance(value, list | tuple) else []
    numbers = [v for v in items if isinstance(v, int | float) and _finite(v)]
    ok = len(items) == 2 and len(numbers) == 2
    if ok and kind is int:
        ok = all(float(v).is_integer() for v in numbers)
    if not ok:
        raise BadValue(f"{name} must be two {'integers' if kind is int else 'numbers'} (lo, hi), got {value!r}")
    return kind(numbers[0]), kind(numbers[1])


def _strings(name: str, value: object) -> tuple[str, ...]:
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list | tuple) or not all(isinstance(v, str) for v in items):
        raise BadValue(f"{name} must be a list of names, got {value!r}")
    return tuple(items)
