"""DAgger's mixing and labelling (tools.dagger.mixing) and its beta schedules (tools.dagger.beta), issue 51 item 6."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")

from gymnasium import spaces  # noqa: E402

from protocol.errors import BadValue  # noqa: E402
from tools.dagger.beta import ConstantBetaSchedule, ExponentialBetaSchedule, LinearBetaSchedule  # noqa: E402
from tools.dagger.config import DaggerConfig  # noqa: E402
from tools.dagger.mixing import AskedCommand, ExpertMixing  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LEARNER = np.array([0.9], np.float32)  # never the stub's expert, whose actions lie in (-0.5, 0.5)


class Stub(gym.Env):
    """A one-number world: the expert steers back towards 0 from where the car is (the observation); each
    episode starts somewhere new and lasts ``episode_steps`` steps."""

    observation_space = spaces.Box(-100.0, 100.0, (1,), np.float32)
    action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, episode_steps: int = 7) -> None:
        self.episode_steps = episode_steps
        self.sent: list[float] = []
        self.state = 0.0
        self.t = 0

    @staticmethod
    def expert(observation: np.ndarray) -> np.ndarray:
        return np.array([-0.5 * np.tanh(float(observation[0]))], np.float32)

    def _observe(self) -> tuple[np.ndarray, dict[str, Any]]:
        obs = np.array([self.state], np.float32)
        return obs, {"expert_action": self.expert(obs)}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.state, self.t = float(self.np_random.uniform(-5.0, 5.0)), 0
        return self._observe()

    def step(self, action):
        self.sent.append(float(action[0]))
        self.state += float(action[0])
        self.t += 1
        obs, info = self._observe()
        return obs, 0.0, False, self.t >= self.episode_steps, info


def _drive(env: ExpertMixing, steps: int, seed: int | None = 0) -> list[bool]:
    """Who drove each of ``steps`` steps (True: the expert), resetting at each episode's end."""
    env.reset(seed=seed)
    drivers = []
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(LEARNER)
        assert env.last is not None
        drivers.append(env.last.by_expert)
        if terminated or truncated:
            env.reset()
    return drivers


def test_the_schedules():
    assert [LinearBetaSchedule(4)(r) for r in range(6)] == [1.0, 0.75, 0.5, 0.25, 0.0, 0.0]
    assert [ExponentialBetaSchedule(0.8, 0.5)(r) for r in range(3)] == [1.0, 0.4, 0.2]
    assert ConstantBetaSchedule()(7) == 1.0
    # rbc dagger's rule is a schedule object: the config's beta is its schedule's
    dagger, bc = DaggerConfig(beta0=0.8, beta_decay=0.5), DaggerConfig(mode="bc")
    assert dagger.beta_schedule() == ExponentialBetaSchedule(0.8, 0.5)
    assert [dagger.beta(r) for r in range(4)] == [1.0, 0.4, 0.2, 0.1]
    assert bc.beta_schedule() == ConstantBetaSchedule(1.0) and bc.beta(3) == 1.0
    for bad in (lambda: LinearBetaSchedule(0), lambda: ExponentialBetaSchedule(1.5), lambda: LinearBetaSchedule(3)(-1),
                lambda: ConstantBetaSchedule(float("nan"))):
        with pytest.raises(BadValue):
            bad()


@pytest.mark.parametrize("beta", [0.0, 0.25, 0.7, 1.0])
def test_the_expert_acts_with_probability_beta_and_its_action_is_sent(beta):
    stub = Stub()
    env = ExpertMixing(stub, beta, keep=True)
    drivers = _drive(env, 4000)
    assert np.mean(drivers) == pytest.approx(beta, abs=0.03)  # 4000 draws: 4 standard deviations at most
    sent = [float(s.action[0]) for s in env.steps]
    assert sent == stub.sent  # what the environment got is what the record says was sent
    assert all(s.action[0] == (s.label[0] if s.by_expert else LEARNER[0]) for s in env.steps)
    assert all(s.learner is not None and s.learner[0] == LEARNER[0] for s in env.steps)


def test_every_step_is_labelled_by_the_expert_reset_steps_included():
    env = ExpertMixing(Stub(episode_steps=3), 0.5, keep=True)
    _drive(env, 30)
    first_steps = env.steps[::3]  # each episode's first step: an observation from reset()
    assert len(env.steps) == 30 and len(first_steps) == 10
    for s in env.steps:  # the label is the expert's action for the observation the step was chosen on
        np.testing.assert_array_equal(s.label, Stub.expert(s.observation))
    # the learner drove some steps: their labels are still the expert's, not what was sent
    assert any(not s.by_expert and s.action[0] != s.label[0] for s in env.steps)


def test_labels_under_sb3s_auto_reset_are_the_new_episodes():
    """A vector env of SB3 resets the wrapper inside it as soon as an episode ends: the next step's label is the
    new episode's first observation's, never the terminal state's."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import DummyVecEnv

    vec = DummyVecEnv([lambda: ExpertMixing(Stub(episode_steps=4), 0.5, keep=True)])
    vec.seed(3)
    vec.reset()
    for _ in range(20):
        vec.step(np.array([LEARNER]))
    steps = vec.envs[0].steps
    assert len(steps) == 20
    for s in steps:
        np.testing.assert_array_equal(s.label, Stub.expert(s.observation))


def test_the_same_seed_gives_the_same_decisions():
    assert _drive(ExpertMixing(Stub(), 0.5), 200, seed=11) == _drive(ExpertMixing(Stub(), 0.5), 200, seed=11)
    assert _drive(ExpertMixing(Stub(), 0.5), 200, seed=11) != _drive(ExpertMixing(Stub(), 0.5), 200, seed=12)
    # one generator given to the environments of a round: one stream of decisions, one draw a step, across them
    shared = np.random.default_rng(5)
    split = _drive(ExpertMixing(Stub(), 0.5, rng=shared), 50) + _drive(ExpertMixing(Stub(), 0.5, rng=shared), 70)
    assert split == list(np.random.default_rng(5).random(120) < 0.5)


def test_without_a_learner_only_beta_one_drives_and_stepping_needs_a_reset():
    env = ExpertMixing(Stub(), 1.0)
    env.reset(seed=0)
    env.step(None)
    assert env.last is not None and env.last.learner is None and env.last.by_expert
    mixed = ExpertMixing(Stub(), 0.5)
    mixed.reset(seed=0)
    with pytest.raises(BadValue, match="needs the learner's action"):
        mixed.step(None)
    with pytest.raises(gym.error.ResetNeeded):
        ExpertMixing(Stub(), 0.5).step(LEARNER)
    with pytest.raises(BadValue, match="beta must be in"):
        ExpertMixing(Stub(), 1.5)


def test_on_the_drive_env_the_label_is_the_experts_on_every_frame():
    """rbc/Drive-v0 through gym.make's wrappers: each step's label is what the environment's expert says for the
    observation it came with, at the first frame of every episode too; the asked command is the sent action's."""
    from tools.envs import ENV_ID

    env = ExpertMixing(AskedCommand(gym.make(ENV_ID, track="lake", spawn="random", max_episode_steps=4)), 0.5,
                       keep=True)
    expert_now = env.get_wrapper_attr("expert_action")  # DriveEnv's public methods, through the wrapper chain
    command = env.get_wrapper_attr("command")
    learner = np.array([0.3], np.float32)
    env.reset(seed=2)
    expected = []
    for _ in range(10):
        expected.append(expert_now())
        asked = {True: command(expected[-1]), False: command(learner)}  # at the speed before the step
        _, _, terminated, truncated, info = env.step(learner)
        assert env.last is not None and info["command"] == asked[env.last.by_expert]
        if terminated or truncated:
            env.reset()
    env.close()
    assert {s.by_expert for s in env.steps} == {True, False}
    for step, label in zip(env.steps, expected, strict=True):
        np.testing.assert_array_equal(step.label, label)


def test_dagger_never_reaches_into_the_environment():
    """Issue 51: the rollout reached into ``env.unwrapped`` for the simulator's command and control rate."""
    offenders = [f"{path.relative_to(ROOT)}:{number}" for path in sorted((ROOT / "tools" / "dagger").glob("*.py"))
                 for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
                 if re.search(r"\bunwrapped\b", line)]
    assert offenders == []
