"""Beta schedules: a round's beta, the probability that the expert acts on a step (``imitation``'s pattern).

A schedule is a callable object ``schedule(round_) -> beta`` for rounds 0, 1, 2, ...; :class:`ExpertMixing`
(:mod:`tools.dagger.mixing`) mixes with the beta it gives. ``rbc dagger``'s rule is
:class:`ExponentialBetaSchedule` (1 in round 0, ``beta0 * decay ** round_`` after it) and its behavioral-cloning
baseline's :class:`ConstantBetaSchedule` (1: the expert every round); :class:`LinearBetaSchedule` is the
``imitation`` library's default. Kept apart from the wrapper: the config needs a schedule, not Gymnasium.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from protocol.errors import BadValue


class BetaSchedule(Protocol):
    """A round's beta, in [0, 1]."""

    def __call__(self, round_: int) -> float: ...


def _check_round(round_: int) -> None:
    if not isinstance(round_, int) or isinstance(round_, bool) or round_ < 0:
        raise BadValue(f"a round is a whole number >= 0, got {round_!r}")


def _check_probability(name: str, value: float) -> None:
    if not (isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
            and 0.0 <= value <= 1.0):
        raise BadValue(f"{name} must be in [0, 1], got {value!r}")


@dataclass(frozen=True)
class ConstantBetaSchedule:
    """The same beta every round (1: the expert acts on every step, behavioral cloning)."""

    beta: float = 1.0

    def __post_init__(self) -> None:
        _check_probability("beta", self.beta)

    def __call__(self, round_: int) -> float:
        _check_round(round_)
        return float(self.beta)


@dataclass(frozen=True)
class ExponentialBetaSchedule:
    """1 in round 0 (there is no learner yet), ``beta0 * decay ** round_`` from round 1 on."""

    beta0: float = 1.0
    decay: float = 0.5

    def __post_init__(self) -> None:
        _check_probability("beta0", self.beta0)
        _check_probability("beta_decay", self.decay)

    def __call__(self, round_: int) -> float:
        _check_round(round_)
        return 1.0 if round_ == 0 else float(self.beta0 * self.decay ** round_)


@dataclass(frozen=True)
class LinearBetaSchedule:
    """From 1 in round 0 down to 0 in round ``rampdown_rounds`` in equal steps, 0 after it."""

    rampdown_rounds: int

    def __post_init__(self) -> None:
        if not isinstance(self.rampdown_rounds, int) or isinstance(self.rampdown_rounds, bool) \
                or self.rampdown_rounds < 1:
            raise BadValue(f"rampdown_rounds must be a whole number >= 1, got {self.rampdown_rounds!r}")

    def __call__(self, round_: int) -> float:
        _check_round(round_)
        return max(0.0, 1.0 - round_ / self.rampdown_rounds)
