"""imitation's behavioral cloning and DAgger run on rbc/Drive-v0 with the simulator's autopilot as the expert.

imitation 1.0.1 is installed beside the rl extra without its pins (requirements-imitation.txt says why and how);
without it these tests are skipped.
"""

from __future__ import annotations

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")
pytest.importorskip("stable_baselines3", reason="imitation needs the rl extra (pip install -e '.[rl]')")
torch = pytest.importorskip("torch", reason="imitation needs torch (the train extra)")
pytest.importorskip("imitation", reason="imitation is not installed: pip install -r requirements-imitation.txt "
                                        "&& pip install --no-deps imitation==1.0.1")
pytest.importorskip("datasets", reason="imitation's DAgger saves its rounds with datasets: "
                                       "pip install -r requirements-imitation.txt")

from imitation.algorithms import bc  # noqa: E402
from imitation.algorithms.dagger import SimpleDAggerTrainer  # noqa: E402
from imitation.data import rollout, serialize  # noqa: E402
from imitation.data.wrappers import RolloutInfoWrapper  # noqa: E402
from imitation.util import logger as imitation_logger  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402

from tools.envs import ExpertPolicy  # noqa: E402

#: jsonpickle 4 warns at each round DAgger saves, torch 2.13 at each loss BC logs: imitation 1.0.1's code, not ours
pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore:keys will default to True:DeprecationWarning"),
              pytest.mark.filterwarnings("ignore:Converting a tensor with requires_grad=True:UserWarning")]

#: short episodes of the network's own 64x64 input, no JPEG round trip: cheap steps
KWARGS = {"track": "lake", "observation": "model", "jpeg": False, "max_episode_steps": 40}


def vec_env(n_envs: int = 2, seed: int = 0):
    return make_vec_env("tools.envs:rbc/Drive-v0", n_envs=n_envs, env_kwargs=KWARGS, seed=seed,
                        wrapper_class=RolloutInfoWrapper)  # what imitation's rollouts unwrap the episodes from


def negative_log_likelihood(trainer: bc.BC, transitions) -> float:
    """BC's loss without its regularisers: -log p(expert action | observation) under the trained policy."""
    with torch.no_grad():
        obs = torch.as_tensor(np.array(transitions.obs), device=trainer.policy.device)
        acts = torch.as_tensor(np.array(transitions.acts), device=trainer.policy.device)
        _, log_prob, _ = trainer.policy.evaluate_actions(obs, acts)
    return -float(log_prob.mean())


def test_behavioral_cloning_learns_from_the_expert_rollouts(tmp_path):
    torch.set_num_threads(1)  # the machine's other core is someone else's
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    venv = vec_env()
    expert = ExpertPolicy(venv)  # imitation's policy callable, bound to venv's current states
    trajectories = rollout.rollout(expert, venv, rollout.make_sample_until(min_timesteps=240), rng=rng,
                                   exclude_infos=False)  # keep them: the expert's labels are checked below
    venv.close()
    for trajectory in trajectories:
        assert len(trajectory.acts) == 40 and trajectory.obs.shape == (41, 64, 64, 3)
        # each step's info labels the observation after it: the next action the expert took
        labels = np.stack([info["expert_action"] for info in trajectory.infos[:-1]])
        np.testing.assert_array_equal(trajectory.acts[1:], labels)
        assert np.abs(trajectory.acts).max() > 0  # it steers
    transitions = rollout.flatten_trajectories(trajectories)
    assert len(transitions) >= 240
    trainer = bc.BC(observation_space=venv.observation_space, action_space=venv.action_space,
                    demonstrations=transitions, rng=rng, batch_size=32, optimizer_kwargs={"lr": 1e-2}, device="cpu",
                    custom_logger=imitation_logger.configure(tmp_path, ["csv"]))  # not a folder in /tmp
    before = negative_log_likelihood(trainer, transitions)
    trainer.train(n_epochs=2, progress_bar=False, log_interval=1000)
    after = negative_log_likelihood(trainer, transitions)
    assert after < before - 0.1, (before, after)


def test_simple_dagger_runs_rounds_with_the_expert_as_an_sb3_policy(tmp_path):
    torch.set_num_threads(1)
    torch.manual_seed(0)
    rng = np.random.default_rng(1)
    venv = vec_env(seed=1)
    expert = ExpertPolicy(venv)
    log = imitation_logger.configure(tmp_path / "log", ["csv"])
    learner = bc.BC(observation_space=venv.observation_space, action_space=venv.action_space, rng=rng,
                    batch_size=32, device="cpu", custom_logger=log)
    trainer = SimpleDAggerTrainer(venv=venv, scratch_dir=tmp_path, expert_policy=expert.sb3(), bc_trainer=learner,
                                  rng=rng, custom_logger=log)
    trainer.train(total_timesteps=160, rollout_round_min_episodes=2, rollout_round_min_timesteps=80,
                  bc_train_kwargs={"n_epochs": 1, "progress_bar": False})
    venv.close()
    assert trainer.round_num == 2
    rounds = sorted((tmp_path / "demos").iterdir())
    assert [r.name for r in rounds] == ["round-000", "round-001"]
    # what each round saved: the expert's labels of the states the mixed policy visited
    demos = [demo for r in rounds for path in sorted(r.iterdir()) for demo in serialize.load(path)]
    assert len(demos) >= 4 and sum(len(d.acts) for d in demos) >= 160
    for demo in demos:
        labels = np.stack([info["expert_action"] for info in demo.infos[:-1]])
        np.testing.assert_array_equal(demo.acts[1:], labels)
