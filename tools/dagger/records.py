"""The records of a DAgger run, as ``record.json`` (one per round) and ``comparison.json`` hold them.

Written by :mod:`tools.dagger.loop` and :mod:`tools.dagger.scoring`, read by :mod:`tools.dagger.summary` and
:mod:`tools.dagger.report`: one declaration of the keys each of them reads.
"""

from __future__ import annotations

from typing import Literal, NotRequired, Required, TypedDict

from models.networks.runfiles import Resolved


class WorstWorld(TypedDict):
    seed: int
    eta: float


class WorldScore(TypedDict):
    seed: int
    eta: float
    takeovers: int


class WorldsScores(TypedDict):
    """The unseen evaluation worlds, one lap each (present when the run scores any)."""

    n: int
    mean: float
    std: float
    worst: WorstWorld
    autonomous: int  # worlds driven without a take-over
    at_target: int  # worlds driven at >= TARGET_ETA
    takeovers: int
    per_world: list[WorldScore]


class TrackScore(TypedDict):
    eta: float
    takeovers: int
    autonomous: bool


class RangeScore(TypedDict, total=False):
    """A Table 9 range search as the round keeps it: the offsets of its ends from the default (None: none)."""

    lower: float | None
    upper: float | None
    unit: str
    empty: bool  # only in an empty range's
    text: str
    lower_at_cap: bool
    upper_at_cap: bool


class AllScores(TypedDict):
    """The worlds and the tracks together."""

    runs: int
    mean: float
    worst: float
    takeovers: int


class RoundScores(TypedDict, total=False):
    """A round's model scored as ``rbc eval`` scores it (:func:`tools.dagger.scoring.evaluate_model`), built key
    by key in the record's order: ``tracks`` and ``all`` are always there, ``worlds`` and ``perturbations`` when
    the run scores them."""

    camera_rig: Required[str]
    worlds: WorldsScores
    tracks: dict[str, TrackScore]
    perturbations: dict[str, RangeScore]
    all: AllScores


class TrainingSummary(TypedDict):
    """What a round's record keeps of its training run."""

    recipe: str
    config: dict[str, object]  # the run's stored configuration, its paths relative to the run's folder
    resolved: Resolved
    val_loss: float
    train_loss: float
    epochs: int


class CollectionRecord(TypedDict):
    """A round's collection (:class:`tools.dagger.rollout.CollectionStats`)."""

    frames: int
    episodes: int
    expert_steps: int
    learner_steps: int
    takeovers: int
    abs_disagreement: float
    world_seeds: list[int]


class Target(TypedDict):
    eta: float
    every_world: bool
    worlds_at_target: int


class RoundRecord(TypedDict):
    """``round-RR/record.json``: a finished round."""

    round: int
    mode: str
    beta: float
    frames_new: int
    expert_frames: int
    collection: CollectionRecord
    learner_sha256: str | None
    training: TrainingSummary
    model: str  # relative to the run's folder
    model_sha256: str
    eval: RoundScores
    target: Target
    seed: int
    config: dict[str, object]  # DaggerConfig.to_dict()
    code_version: str
    timing: NotRequired[dict[str, float]]  # the only part a resumed run may give differently


class BestRound(TypedDict):
    """DAgger's best round where none reached the target: the most worlds at the target, then the best worst."""

    expert_frames: int
    worlds_at_target: int | None
    worlds_n: int | None
    worst: float | None


class VerdictFrames(TypedDict):
    """The expert frames each method needed to drive every unseen world at the target (None: never)."""

    target_eta: float
    dagger_frames: int | None
    bc_frames: int | None
    bc_most_frames: int
    bc_reached: bool
    met: bool


class Verdict(VerdictFrames, total=False):
    """Issue #46's target against behavioral cloning at equal expert frames (:func:`tools.dagger.report.verdict`):
    ``dagger_best`` where DAgger never reached it, ``ratio`` where it did."""

    dagger_best: BestRound | None
    ratio: float
    text: Required[str]


#: The built-in tracks whose columns the comparison's curve draws, by their summary keys.
CurveKey = Literal["lake_eta", "mountain_eta"]


class SummaryRow(TypedDict, total=False):
    """One round of ``summary.json`` as the comparison reads it (:func:`tools.dagger.summary.round_row`). Each
    scored track adds ``NAME_eta`` and ``NAME_takeovers`` and each perturbation its text; the keys of the default
    tracks, which the curve draws, are declared."""

    round: int
    mode: str
    beta: float
    expert_frames: int
    learner_steps: int
    collection_takeovers: int
    worlds_mean: float
    worlds_worst: float
    worlds_at_target: int
    worlds_n: int
    worlds_takeovers: int
    lake_eta: float
    lake_takeovers: int
    mountain_eta: float
    mountain_takeovers: int
    all_mean: float
    all_worst: float
    all_takeovers: int


class ComparedRow(SummaryRow, total=False):
    """A round of either method in the comparison: its method's name, and whether it drove every world at the
    target."""

    method: str
    every_world: bool


class SummaryDocument(TypedDict):
    """``summary.json``: the run's mode, config and seed, the code version and every finished round's row."""

    mode: str
    config: dict[str, object]  # DaggerConfig.to_dict()
    seed: int
    code_version: str
    rounds: list[SummaryRow]
