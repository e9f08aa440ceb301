"""What defines a DAgger (or behavioral-cloning baseline) run, and the per-round numbers derived from it.

One frozen dataclass, checked on construction, so a bad value is a :class:`protocol.errors.BadValue` naming it
before anything is written. ``to_dict`` is what ``OUT/dagger.json`` and every round's record keep; a resumed run
must find the same dict there (only the budgets may grow: more rounds appended to a finished run).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from typing import Any

from protocol.errors import BadValue
from protocol.facts import DEPLOY_SPEED_KMH
from tools.dagger.beta import BetaSchedule, ConstantBetaSchedule, ExponentialBetaSchedule
from tools.sim.render.camera import RIGS
from tools.sim.worldgen import WorldGenConfig, world_seed_range

MODES = ("dagger", "bc")
#: The built-in tracks every round is also scored on (never trained on: training drives generated worlds only).
TRACKS = ("lake", "mountain")
#: Table 9's orientation and light rows, scored on lake as ``rbc eval`` runs them (``--perturbations``).
PERTURBATIONS = ("orientation", "light_intensity", "light_direction")
#: The bundled training recipe of a round (models/recipes/dagger.toml).
DEFAULT_RECIPE = "dagger"

# Independent random streams of one round, each seeded [seed, round, stream]: adding a stream never moves another.
STREAM_EPISODES = 0  # the world and the reset seed of each episode
STREAM_MIX = 1  # who drives each step (the expert with probability beta)


@dataclass(frozen=True)
class DaggerConfig:
    """``rbc dagger``'s settings. ``budgets``: the expert-labelled frames after each round (cumulative)."""

    mode: str = "dagger"  # "dagger": the learner drives from round 1 on; "bc": the expert drives every round
    budgets: tuple[int, ...] = (2000, 4000, 8000, 16000)
    beta0: float = 1.0  # beta (the probability that the expert drives a step) of round r >= 1: beta0 * beta_decay ** r
    beta_decay: float = 0.5  # (round 0 is the expert's alone; "bc" keeps beta = 1 in every round)
    episode_steps: int = 400  # steps (1/15 s) per episode, each on a new training world from a random spot
    recipe: str = DEFAULT_RECIPE  # rbc train's recipe of every round (a bundled name or a .toml file)
    epochs: int | None = None  # instead of the recipe's
    max_steps_per_epoch: int | None = None  # instead of the recipe's (tests: a few steps)
    eval_worlds: int = 20  # unseen generated worlds from the evaluation range, one lap each
    eval_world_seed: int | None = None  # the first of them (None: the start of the evaluation range)
    eval_world_config: dict[str, object] | None = None  # WorldGenConfig fields of the evaluation worlds (None: default)
    tracks: tuple[str, ...] = TRACKS  # built-in tracks scored too, one lap each
    perturbations: bool = False  # also Table 9's orientation and light rows on lake (range searches)
    laps: int = 1  # laps per evaluation run
    seed: int = 0  # worlds, spawns, who drives, and the training seed of every round
    cameras: int = 1  # frames recorded per step: 1 (centre) or 3 (centre, left, right: the recipe's side cameras)
    camera: str = "unity"  # the camera rig of the recorded frames (and so of the models)
    speed_limit_kmh: float = DEPLOY_SPEED_KMH  # Eq. 14's limit while collecting and evaluating (rbc eval's default)
    action_delay: int = 1  # each command applies a step late, as with Unity and rbc eval's two frames in flight

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise BadValue(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        budgets = tuple(self.budgets)
        object.__setattr__(self, "budgets", budgets)
        if not budgets or any(not isinstance(b, int) or isinstance(b, bool) for b in budgets):
            raise BadValue(f"budgets must be a list of whole numbers of frames, got {self.budgets!r}")
        if budgets[0] < 1 or any(b <= a for a, b in zip(budgets, budgets[1:], strict=False)):
            raise BadValue(f"budgets must rise from at least 1 frame (the expert frames after each round), "
                           f"got {', '.join(map(str, budgets))}")
        for name in ("beta0", "beta_decay"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and 0.0 <= value <= 1.0):
                raise BadValue(f"{name} must be in [0, 1], got {value!r}")
        for name, low in (("episode_steps", 10), ("eval_worlds", 0), ("laps", 1), ("action_delay", 0)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise BadValue(f"{name} must be a whole number >= {low}, got {value!r}")
        for name in ("epochs", "max_steps_per_epoch"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, int) or value < 1):
                raise BadValue(f"{name} must be a whole number >= 1, got {value!r}")
        if self.action_delay > 1:
            raise BadValue(f"action_delay must be 0 or 1, got {self.action_delay}")
        if self.cameras not in (1, 3):
            raise BadValue(f"cameras must be 1 or 3, got {self.cameras!r}")
        if self.camera not in RIGS:
            raise BadValue(f"camera must be one of {', '.join(RIGS)}, got {self.camera!r}")
        if not (math.isfinite(self.speed_limit_kmh) and self.speed_limit_kmh > 0):
            raise BadValue(f"speed_limit_kmh must be a positive number, got {self.speed_limit_kmh!r}")
        object.__setattr__(self, "tracks", tuple(self.tracks))
        if self.eval_world_config is not None:
            self.world_gen_config()  # an unknown field or a bad value is a BadValue now
        if not self.eval_worlds and not self.tracks:
            raise BadValue("nothing to score the rounds on: give eval_worlds >= 1 or at least one track")
        held_out = world_seed_range("eval")
        if self.eval_worlds:
            first = held_out.start if self.eval_world_seed is None else self.eval_world_seed
            if first not in held_out or first + self.eval_worlds - 1 not in held_out:
                raise BadValue(f"evaluation worlds come from the evaluation seeds {held_out.start:,}-"
                               f"{held_out.stop - 1:,}, not {first}-{first + self.eval_worlds - 1}")

    @property
    def rounds(self) -> int:
        return len(self.budgets)

    def new_frames(self, round_: int) -> int:
        """Expert-labelled frames collected in round ``round_``."""
        return self.budgets[round_] - (self.budgets[round_ - 1] if round_ else 0)

    def beta_schedule(self) -> BetaSchedule:
        """Who drives, round by round: in "dagger" 1 in round 0 (there is no learner yet: behavioral cloning on
        the expert's laps) and beta0 * beta_decay ** round_ after that; in "bc" 1 in every round."""
        if self.mode == "bc":
            return ConstantBetaSchedule(1.0)
        return ExponentialBetaSchedule(self.beta0, self.beta_decay)

    def beta(self, round_: int) -> float:
        """The probability that the expert drives a step in round ``round_`` (:meth:`beta_schedule`)."""
        return self.beta_schedule()(round_)

    def world_gen_config(self) -> WorldGenConfig:
        """The generator settings of the evaluation worlds (``rbc eval --world-config``'s rules)."""
        from tools.sim.worldgen.config import parse_world_config

        if not isinstance(self.eval_world_config, dict | None):
            raise BadValue(f"eval_world_config must be a dict of WorldGenConfig fields, got {self.eval_world_config!r}")
        return parse_world_config(json.dumps(self.eval_world_config or {}))

    def eval_seeds(self) -> list[int]:
        first = world_seed_range("eval").start if self.eval_world_seed is None else self.eval_world_seed
        return list(range(first, first + self.eval_worlds))

    def to_dict(self) -> dict[str, object]:
        out = asdict(self)
        out["budgets"] = list(self.budgets)
        out["tracks"] = list(self.tracks)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DaggerConfig:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise BadValue(f"unknown DAgger setting(s): {', '.join(unknown)}")
        values = dict(data)
        for key in ("budgets", "tracks"):
            if key in values:
                values[key] = tuple(values[key])
        return cls(**values)

    def same_run(self, other: DaggerConfig) -> bool:
        """Whether ``other`` continues this run: every setting equal, its budgets this run's or more."""
        mine, theirs = self.to_dict(), other.to_dict()
        del mine["budgets"], theirs["budgets"]
        return mine == theirs and other.budgets[:len(self.budgets)] == self.budgets


def budgets_from(rounds: int, frames_per_round: int) -> tuple[int, ...]:
    """``rounds`` rounds of ``frames_per_round`` new expert frames each, as cumulative budgets."""
    if rounds < 1 or frames_per_round < 1:
        raise BadValue(f"--rounds and --frames-per-round must be >= 1, got {rounds} and {frames_per_round}")
    return tuple(frames_per_round * (r + 1) for r in range(rounds))
