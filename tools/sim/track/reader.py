"""Typed accessors for a decoded track file: a bad value becomes a TrackError naming the file and the key."""

from __future__ import annotations

import math
from typing import NoReturn

from tools.sim.track.road import TrackError


class Reader:
    """Small typed accessors that turn bad values into TrackErrors naming the file."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, problem: str) -> NoReturn:
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
