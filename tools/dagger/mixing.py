"""DAgger's mixing and labelling as a Gymnasium wrapper (the pattern of ``imitation``'s interactive collector).

Each step the wrapper takes the learner's action and, with probability beta (a round's, from a
:mod:`~tools.dagger.beta` schedule), sends the expert's instead; whoever acted, the observation the action was
chosen on is recorded with the expert's action as its label. The expert is the environment's own, read from the
public ``info["expert_action"]`` that ``rbc/Drive-v0`` returns with every observation, reset's included: the
label of the observation it comes with. The wrapper never reaches inside the environment, so it wraps any
environment that gives that key. :class:`AskedCommand` adds the steer command each action asked for, which
``rbc dagger``'s recording logs.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Generic, SupportsFloat, TypeVar

import gymnasium as gym
import numpy as np

from protocol.errors import BadValue

#: The key of the expert's action in every reset's and step's info.
LABEL_KEY = "expert_action"
#: The mixing stream of a wrapper seeded by ``reset(seed=...)`` (apart from the environment's own draws).
MIX_STREAM = 0xDA6

#: The wrapped environment's observation (``rbc/Drive-v0``: a frame, or frames by camera).
ObsT = TypeVar("ObsT")
#: An action as the environment takes it and the expert's label (``rbc/Drive-v0``: float32, steering first).
Action = np.ndarray


@dataclass(frozen=True)
class MixedStep(Generic[ObsT]):
    """One step of a mixed rollout: the observation the action was chosen on, labelled by the expert."""

    observation: ObsT
    label: np.ndarray  # the expert's action for ``observation``: the DAgger label
    learner: np.ndarray | None  # the learner's action for it (None: no learner was asked, beta 1)
    by_expert: bool  # whether the expert's action was sent
    action: np.ndarray  # the action sent to the environment


class ExpertMixing(gym.Wrapper[ObsT, Action, ObsT, Action]):
    """``step(learner_action)`` sends the expert's action with probability ``beta``, the learner's otherwise.

    ``rng``: the stream of the mixing decisions, one draw a step (``imitation`` passes one; give the same
    generator to the environments of one round to draw one stream across them). Without it ``reset(seed=s)``
    seeds the wrapper's own stream, as Gymnasium seeds ``np_random``: the same seed, the same decisions.
    ``keep``: keep every step's :class:`MixedStep` in :attr:`steps` (observations and labels: a data set in
    memory); :attr:`last` is always the latest step's. A learner's action of None is allowed only with beta 1.
    """

    def __init__(self, env: gym.Env[ObsT, Action], beta: float, rng: np.random.Generator | None = None,
                 keep: bool = False) -> None:
        super().__init__(env)
        if not (isinstance(beta, int | float) and not isinstance(beta, bool) and 0.0 <= beta <= 1.0):
            raise BadValue(f"beta must be in [0, 1], got {beta!r}")
        self.beta = float(beta)
        self._own_stream = rng is None
        self.mix_rng = rng if rng is not None else np.random.default_rng()
        self.keep = keep
        self.steps: list[MixedStep[ObsT]] = []
        self.last: MixedStep[ObsT] | None = None
        self._seen: tuple[ObsT, np.ndarray] | None = None  # the current observation and its label

    @property
    def label(self) -> np.ndarray:
        """The expert's action for the current observation."""
        return self._current()[1].copy()

    def _current(self) -> tuple[ObsT, np.ndarray]:
        if self._seen is None:
            raise gym.error.ResetNeeded("ExpertMixing: no observation yet, call reset() first")
        return self._seen

    # info: Gymnasium's type of a step's and a reset's info
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[ObsT, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        if seed is not None and self._own_stream:
            self.mix_rng = np.random.default_rng([seed, MIX_STREAM])
        self._see(obs, info)
        return obs, info

    def step(self, action: Action | None) -> tuple[ObsT, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, label = self._current()
        label = label.copy()
        if action is None and self.beta < 1.0:
            raise BadValue(f"ExpertMixing with beta {self.beta:g} needs the learner's action on every step, got None")
        learner = None if action is None else np.asarray(action, dtype=label.dtype).reshape(label.shape)
        by_expert = bool(self.mix_rng.random() < self.beta)  # one draw a step, whoever acts
        sent = label if by_expert or learner is None else learner
        obs, reward, terminated, truncated, info = self.env.step(sent)
        self.last = MixedStep(observation, label, learner, by_expert, sent)
        if self.keep:
            self.steps.append(self.last)
        self._see(obs, info)
        return obs, reward, terminated, truncated, info

    def _see(self, obs: ObsT, info: Mapping[str, object]) -> None:
        if LABEL_KEY not in info:
            raise BadValue(f"ExpertMixing labels with info[{LABEL_KEY!r}], which {self.env} does not give")
        self._seen = obs, np.array(info[LABEL_KEY], dtype=np.float32)  # a copy: a later relabelling leaves it


class AskedCommand(gym.Wrapper[ObsT, Action, ObsT, Action]):
    """Adds ``info["command"]`` to each step: the steer command its action asked for, by the environment's
    public ``command(action)`` (``rbc/Drive-v0``: Eq. 14's throttle at the speed before the step)."""

    def step(self, action: Action) -> tuple[ObsT, SupportsFloat, bool, bool, dict[str, Any]]:
        command = self.env.get_wrapper_attr("command")(action)
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["command"] = command  # in place: the environment may still relabel this info (SB3's auto-reset)
        return obs, reward, terminated, truncated, info
