"""The autopilot's :class:`tools.envs.expert.ExpertPolicy` as a Stable-Baselines3 ``BasePolicy``.

Apart from ``expert.py`` because it imports SB3 and torch (the ``rl`` extra), which the expert itself does
not need. ``imitation`` calls ``predict`` only on SB3 policies and algorithms where it asks for a
deterministic expert (its DAgger), so there the expert must be one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy

if TYPE_CHECKING:
    from tools.envs.policy import Observation


class ExpertPolicy(Protocol):
    """What this module uses of :class:`tools.envs.expert.ExpertPolicy` (which imports it: no import back)."""

    observation_space: spaces.Space[Observation]
    action_space: spaces.Space[np.ndarray]

    def labels(self) -> np.ndarray: ...

    def predict(self, observation: np.ndarray | dict[str, np.ndarray], state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]: ...


class SB3ExpertPolicy(BasePolicy):
    """An SB3 policy without parameters whose actions are the bound environments' autopilot's."""

    def __init__(self, expert: ExpertPolicy) -> None:
        super().__init__(expert.observation_space, expert.action_space)
        self.expert = expert

    def _predict(self, observation: torch.Tensor | dict[str, torch.Tensor],
                 deterministic: bool = False) -> torch.Tensor:
        return torch.as_tensor(self.expert.labels())

    def predict(self, observation: np.ndarray | dict[str, np.ndarray], state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = False) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        return self.expert.predict(observation, state, episode_start, deterministic)
