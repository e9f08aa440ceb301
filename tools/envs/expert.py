"""The simulator's privileged driver (the autopilot) as a policy object for Stable-Baselines3 and ``imitation``.

The autopilot steers from the simulator's state, not from the frame, so the policy is bound to the
environment(s) it labels and reads their :meth:`DriveEnv.expert_action` when asked: ``predict(obs)`` answers for
the observations those environments returned last (as in a rollout), never for stored frames. It needs no
torch; :meth:`ExpertPolicy.sb3` gives the same policy as an SB3 ``BasePolicy`` where one is required.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol, cast

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from protocol.errors import BadValue
from tools.envs.drive_env import DriveEnv

if TYPE_CHECKING:
    from stable_baselines3.common.policies import BasePolicy

    from tools.envs.policy import Observation


class _SB3VecEnv(Protocol):
    """What an SB3 ``VecEnv`` offers that the expert uses (duck-typed: SB3 is the optional ``rl`` extra)."""

    num_envs: int
    observation_space: spaces.Space[Observation]
    action_space: spaces.Space[np.ndarray]

    def env_method(self, method_name: str, *args: object, **kwargs: object) -> list[np.ndarray]: ...


#: What an expert can be bound to: one env, a Gymnasium vector env, or an SB3 VecEnv of them.
DriveEnvs = (gym.Env["Observation", np.ndarray] | gym.vector.VectorEnv["Observation", np.ndarray, np.ndarray]
             | _SB3VecEnv)


class ExpertPolicy:
    """The autopilot's action for each bound environment's current state, with SB3's ``predict`` signature.

    ``env``: one ``rbc/Drive-v0`` (``gym.make``'s, wrapped or not), a Gymnasium vector env of them, or an SB3
    ``VecEnv`` of them (``DummyVecEnv``, ``SubprocVecEnv``, ``make_vec_env``'s). Calling it,
    ``expert(obs, states, episode_starts)``, is ``imitation``'s policy callable.
    """

    def __init__(self, env: DriveEnvs) -> None:
        self.env = env
        if isinstance(env, gym.vector.VectorEnv):
            if not hasattr(env, "call"):  # SyncVectorEnv and AsyncVectorEnv have it; the base class does not
                raise BadValue(f"ExpertPolicy needs a vector env with call(), got {type(env).__name__}")
            self.num_envs = env.num_envs
            self.observation_space: spaces.Space[Observation] = env.single_observation_space
            self.action_space: spaces.Space[np.ndarray] = env.single_action_space
            self.vectorised = True
        elif isinstance(env, gym.Env):
            if not isinstance(env.unwrapped, DriveEnv):
                raise BadValue(f"ExpertPolicy labels rbc/Drive-v0 environments, got {type(env.unwrapped).__name__}")
            self.num_envs = 1
            self.observation_space, self.action_space = env.observation_space, env.action_space
            self.vectorised = False
        elif hasattr(env, "env_method") and hasattr(env, "num_envs"):
            self.num_envs = env.num_envs
            self.observation_space, self.action_space = env.observation_space, env.action_space
            self.vectorised = True
        else:
            raise BadValue(f"ExpertPolicy needs a Gymnasium env, a Gymnasium vector env or an SB3 VecEnv, "
                           f"got {type(env).__name__}")

    def labels(self) -> np.ndarray:
        """The autopilot's actions for the bound environments' current states, shape (num_envs, action size)."""
        env = self.env
        if isinstance(env, gym.vector.VectorEnv):
            actions = list(getattr(env, "call")("expert_action"))  # noqa: B009 (not on VectorEnv's type)
        elif isinstance(env, gym.Env):
            actions = [cast(DriveEnv, env.unwrapped).expert_action()]
        else:
            actions = env.env_method("expert_action")
        return np.stack(actions).astype(np.float32)

    def predict(self, observation: np.ndarray | dict[str, np.ndarray], state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """``(actions, state)`` as SB3's ``BasePolicy.predict``: a batch of actions for a batch of observations
        (one per bound environment), one action for a single environment's unbatched observation. The
        autopilot is deterministic; ``deterministic`` and ``episode_start`` change nothing."""
        frames = np.asarray(observation["center"] if isinstance(observation, dict) else observation)
        image_ndim = len(cast(spaces.Box, self.observation_space["center"] if isinstance(
            self.observation_space, spaces.Dict) else self.observation_space).shape)
        actions = self.labels()
        if frames.ndim == image_ndim and not self.vectorised:
            return actions[0], state
        if frames.ndim != image_ndim + 1 or frames.shape[0] != self.num_envs:
            raise BadValue(f"ExpertPolicy labels the {self.num_envs} bound environment(s)' latest observations, "
                           f"got observations of shape {frames.shape}")
        return actions, state

    def __call__(self, observations: np.ndarray | dict[str, np.ndarray],
                 states: tuple[np.ndarray, ...] | None = None,
                 episode_starts: np.ndarray | None = None) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        return self.predict(observations, states, episode_starts)

    def sb3(self) -> BasePolicy:
        """This policy as a Stable-Baselines3 ``BasePolicy`` (the ``rl`` extra), for code that checks the type:
        ``imitation``'s ``SimpleDAggerTrainer(expert_policy=...)`` and its rollouts with
        ``deterministic_policy=True``."""
        from tools.envs.expert_sb3 import SB3ExpertPolicy

        return SB3ExpertPolicy(self)
