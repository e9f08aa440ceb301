"""The record of ``python -m tools.dagger.rlcompare`` (``OUT/comparison.json``), as small record classes."""

from __future__ import annotations

from typing import TypedDict


class WorldScore(TypedDict):
    seed: int
    eta: float
    takeovers: int


class WorstWorld(TypedDict):
    seed: int
    eta: float


class WorldsScore(TypedDict):
    n: int
    mean: float
    std: float
    worst: WorstWorld
    autonomous: int
    at_target: int
    takeovers: int
    per_world: list[WorldScore]


class TrackScore(TypedDict):
    eta: float
    takeovers: int
    autonomous: bool


class AllScore(TypedDict):
    runs: int
    mean: float
    worst: float
    takeovers: int


class PolicyScores(TypedDict, total=False):
    """One policy's row of the comparison (``worlds`` only with worlds to drive)."""

    name: str
    kind: str
    path: str | None
    camera_rig: str
    worlds: WorldsScore
    tracks: dict[str, TrackScore]
    all: AllScore


class Comparison(TypedDict):
    """``OUT/comparison.json``."""

    what: str
    seed: int
    code_version: str
    run_code: str
    target_eta: float
    worlds: dict[str, object] | None
    tracks: list[str]
    policies: list[PolicyScores]
