"""The options ``rbc/Drive-v0``'s ``reset(options=...)`` takes to pin one episode's draws, checked up front.

Every option is checked (and normalised) before the reset changes anything, so a bad one is a ``BadValue`` of one
line and the environment stays as it was; a held-out evaluation world is refused unless the environment was made
with ``purpose="eval"``, as ``rbc collect`` refuses it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from protocol.errors import BadValue
from tools.envs.worlds import _strings

#: what ``reset(options=...)`` may pin for one episode
RESET_OPTIONS = ("spawn_s", "cone_seed", "track", "world_seed", "themes", "sun_deg", "light_intensity", "fog")


def check_reset_options(options: dict[str, Any] | None, purpose: str) -> dict[str, Any]:
    """``reset``'s options, checked and normalised (``world_seed`` becomes ``track="world:SEED"``); every bad one
    is a BadValue of one line, before anything changes."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise BadValue(f"reset options must be a dict, got {options!r}")
    unknown = sorted(map(str, set(options) - set(RESET_OPTIONS)))
    if unknown:
        raise BadValue(f"unknown reset option(s): {', '.join(unknown)} (known: {', '.join(RESET_OPTIONS)})")
    pinned = dict(options)
    numbers = {"spawn_s": ("a finite number", lambda v: True),
               "sun_deg": ("an angle in [-90, 90]", lambda v: -90 <= v <= 90),
               "light_intensity": ("a number >= 0", lambda v: v >= 0), "fog": ("a number > 0", lambda v: v > 0)}
    for name, (bounds, ok) in numbers.items():
        value = pinned.get(name)
        if value is None:
            pinned.pop(name, None)
            continue
        if not isinstance(value, int | float) or isinstance(value, bool) or not np.isfinite(value) or not ok(value):
            raise BadValue(f"reset option {name} must be {bounds}, got {value!r}")
        pinned[name] = float(value)
    for name in ("cone_seed", "world_seed"):
        value = pinned.get(name)
        if value is not None and (not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 0):
            raise BadValue(f"reset option {name} must be an integer >= 0, got {value!r}")
    if "world_seed" in pinned and pinned.get("track") is not None:
        raise BadValue("reset options: give track or world_seed, not both")
    if pinned.get("world_seed") is not None:
        pinned["track"] = f"world:{int(pinned.pop('world_seed'))}"
    pinned.pop("world_seed", None)
    track = pinned.get("track")
    if track is not None:
        if not isinstance(track, str) or not track:
            raise BadValue(f"reset option track must be a track name, file or world:SEED, got {track!r}")
        from tools.sim.collect.worlds import training_seed_problem
        from tools.sim.track.files import world_seed_of

        seed = world_seed_of(track)
        problem = training_seed_problem(seed, 1) if seed is not None and purpose == "train" else None
        if problem:
            raise BadValue(f"reset option track={track}: {problem}", "make the environment with purpose='eval' "
                                                                    "to evaluate on it (never train on it)")
    else:
        pinned.pop("track", None)
    if "themes" in pinned:
        from tools.sim.track.road import THEMES

        themes = _strings("reset option themes", pinned["themes"])
        if not themes or set(themes) - set(THEMES):
            raise BadValue(f"reset option themes must be a non-empty list of {', '.join(THEMES)}, "
                           f"got {pinned['themes']!r}")
        pinned["themes"] = tuple(sorted(set(themes)))
    return pinned
