"""Stable-Baselines3's PPO trains on rbc/Drive-v0 (the rl extra): a few thousand steps, a small network."""

from __future__ import annotations

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")
sb3 = pytest.importorskip("stable_baselines3",
                          reason="stable_baselines3 is not installed: PPO on rbc/Drive-v0 needs pip install -e '.[rl]'")
torch = pytest.importorskip("torch", reason="stable_baselines3 needs torch")

import tools.envs  # noqa: E402,F401  (registers rbc/Drive-v0)


@pytest.mark.slow
def test_ppo_trains_a_few_thousand_steps_on_downsampled_frames():
    from gymnasium.wrappers import ResizeObservation
    from stable_baselines3 import PPO

    torch.set_num_threads(1)  # the machine's other core is someone else's
    env = ResizeObservation(gym.make("rbc/Drive-v0", track="lake", jpeg=False, spawn="random"), (40, 80))
    model = PPO("CnnPolicy", env, n_steps=512, batch_size=128, n_epochs=2, seed=0, device="cpu",
                policy_kwargs={"features_extractor_kwargs": {"features_dim": 64}, "net_arch": [32]})
    model.learn(total_timesteps=2048)
    assert model.num_timesteps >= 2048
    obs, _ = env.reset(seed=1)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(np.asarray(action, np.float32))
    _, reward, *_ = env.step(action)
    assert np.isfinite(reward)
    env.close()
