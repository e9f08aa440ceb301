"""rbc/Drive-v0: the headless simulator as a Gymnasium environment (tools.envs)."""

from __future__ import annotations

import base64
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")

from drive_server.serving.model import SteeringModel  # noqa: E402
from drive_server.serving.pipeline import DriveConfig, DrivePipeline  # noqa: E402
from protocol import SpeedUnit, Telemetry  # noqa: E402
from protocol.errors import BadValue  # noqa: E402
from protocol.jpeg import decode_jpeg  # noqa: E402
from tools.envs import ENV_ID, DriveEnv, OnnxPolicy, RewardConfig  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PRETRAINED = REPO / "models" / "pretrained"


@pytest.fixture(scope="module")
def lake() -> DriveEnv:
    env = DriveEnv(track="lake")
    yield env
    env.close()


def _drive(env, steps: int, action=None, seed: int = 0):
    obs, info = env.reset(seed=seed)
    frames, rewards = [obs], []
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(info["expert_action"] if action is None else action)
        frames.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            break
    return frames, rewards, info


def test_importing_the_module_in_make_is_all_it_takes():
    code = ("import gymnasium as gym; env = gym.make('tools.envs:rbc/Drive-v0', track='lake'); "
            "print(env.spec.id, env.observation_space.shape, env.action_space.shape)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [ENV_ID, "(160,", "320,", "3)", "(1,)"]


def test_the_packages_example_runs(capsys):
    import textwrap

    import tools.envs

    doc = tools.envs.__doc__
    example = textwrap.dedent(doc[doc.index("    import gymnasium"):doc.index("Keyword arguments")])
    exec(compile(example, "tools/envs/__init__.py", "exec"), {})
    assert " m, cte " in capsys.readouterr().out


def test_check_env_passes_for_one_and_three_cameras_and_both_controls():
    from gymnasium.utils.env_checker import check_env

    for kwargs in ({"render_mode": "rgb_array"}, {"cameras": 3, "control": "steer_throttle", "jpeg": False}):
        env = gym.make(ENV_ID, track="lake", **kwargs)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # the checker's warnings too
            check_env(env.unwrapped, skip_render_check=False)
        env.close()


def test_the_spaces_and_the_info(lake: DriveEnv):
    obs, info = lake.reset(seed=3)
    assert obs.shape == (160, 320, 3) and obs.dtype == np.uint8
    assert lake.action_space.shape == (1,) and lake.action_space.low[0] == -1 and lake.action_space.high[0] == 1
    for key in ("cte_m", "heading_error_deg", "speed_kmh", "progress_m", "lap_progress", "t_s", "step",
                "expert_action", "intervention", "laps_done", "jpeg"):
        assert key in info, key
    assert info["step"] == 0 and info["speed_kmh"] == 0 and info["intervention"] == ""
    assert lake.action_space.contains(info["expert_action"])
    assert abs(info["cte_m"]) <= 0.5 and abs(info["heading_error_deg"]) <= 3.0  # the spawn's noise


def test_the_observation_is_the_frame_after_the_wires_jpeg(lake: DriveEnv):
    obs, info = lake.reset(seed=1)
    assert np.array_equal(obs, decode_jpeg(info["jpeg"]))  # THE decode of what the wire would carry
    raw = DriveEnv(track="lake", jpeg=False, render_mode="rgb_array")
    obs_raw, info_raw = raw.reset(seed=1)
    assert "jpeg" not in info_raw and np.array_equal(obs_raw, raw.render())
    diff = np.abs(obs.astype(int) - obs_raw.astype(int))
    assert 0 < diff.mean() < 6  # JPEG quality 75: a few grey levels


def test_same_seed_same_episode_other_seed_other_episode(lake: DriveEnv):
    frames_a, rewards_a, _ = _drive(lake, 40, seed=11)
    frames_b, rewards_b, _ = _drive(lake, 40, seed=11)
    assert rewards_a == rewards_b
    assert all(np.array_equal(a, b) for a, b in zip(frames_a, frames_b, strict=True))
    frames_c, _, _ = _drive(lake, 1, seed=12)
    assert not np.array_equal(frames_a[0], frames_c[0])  # another spawn


def test_the_autopilot_drives_and_the_reward_is_the_progress(lake: DriveEnv):
    _, rewards, info = _drive(lake, 300)
    assert len(rewards) == 300 and info["intervention"] == ""
    assert 90 < info["progress_m"] < 140  # 20 s from standstill towards 25 km/h
    assert sum(rewards) == pytest.approx(info["progress_m"], abs=1.0)  # nothing out of the lane
    assert abs(info["cte_m"]) < 0.6 and 18 < info["speed_kmh"] < 27


def test_leaving_the_road_terminates_with_the_penalty():
    env = DriveEnv(track="lake", reward=RewardConfig(takeover=7.0))
    obs, info = env.reset(seed=0)
    rewards = []
    for _ in range(400):
        # half lock left: Eq. 14 still drives on (at full lock it brakes to a stop, a take-over for standing still)
        obs, reward, terminated, truncated, info = env.step([-0.5])
        rewards.append(reward)
        if terminated or truncated:
            break
    assert terminated and not truncated and info["intervention"] == "off_road"
    assert 4.0 < abs(info["cte_m"]) < 5.5  # where it left the road (off at 4.5 m), not where it was put back
    assert rewards[-1] < -6.0  # the termination penalty (less the step's progress)


def test_step_limit_and_laps_truncate():
    env = gym.make(ENV_ID, track="lake", max_episode_steps=5, jpeg=False)
    _, info = env.reset(seed=0)
    for step in range(1, 6):
        _, _, terminated, truncated, info = env.step(info["expert_action"])
        assert truncated == (step == 5) and not terminated
    lap = DriveEnv(track="lake", jpeg=False)
    _, rewards, info = _drive(lap, 4000)
    assert info["laps_done"] and info["lap_progress"] >= 1.0 and info["intervention"] == ""
    assert sum(rewards) == pytest.approx(lap.client.track_length_m, abs=5.0)


def test_three_cameras_are_a_dict_of_the_rig():
    env = DriveEnv(track="lake", cameras=3)
    obs, _ = env.reset(seed=0)
    assert set(obs) == {"center", "left", "right"} and env.observation_space.contains(obs)
    assert not np.array_equal(obs["left"], obs["right"])


def test_steer_control_is_drive_servers_coupled_law(lake: DriveEnv):
    pipeline = DrivePipeline(SteeringModel(PRETRAINED / "generalist.onnx"), DriveConfig(speed_unit=SpeedUnit.MPH))
    _, info = lake.reset(seed=0)
    for _ in range(60):
        _, _, _, _, info = lake.step(info["expert_action"])
    for steering in (-0.8, -0.1, 0.0, 0.3, 1.0):
        command = lake.command([steering])
        expected = pipeline.control(steering, lake.client.wire_speed())
        assert (command.steering, command.throttle) == (expected.steering, expected.throttle)
    throttle_env = DriveEnv(track="lake", control="steer_throttle", law={"speed_limit_kmh": 5.0})
    _, info = throttle_env.reset(seed=0)
    for _ in range(60):
        _, _, _, _, info = throttle_env.step([0.0, 1.0])
    assert info["speed_kmh"] < 8.0  # the governor cuts the throttle at the limit
    assert throttle_env.command([0.0, 1.0]).throttle <= 0.0 or info["speed_kmh"] < 5.0


def test_held_out_worlds_are_refused_for_training():
    for kwargs in ({"world_seed": 1_000_000}, {"track": "world:1000003"}, {"world_seed": 2_000_000}):
        with pytest.raises(BadValue, match="held-out worlds must never be trained on") as exc:
            DriveEnv(**kwargs)
        assert "purpose='eval'" in exc.value.hint
    env = DriveEnv(world_seed=1_000_000, purpose="eval", jpeg=False)
    obs, info = env.reset(seed=0)
    assert obs.shape == (160, 320, 3) and info["intervention"] == ""


@pytest.mark.parametrize("kwargs", [{"cameras": 2}, {"control": "throttle"}, {"camera": "fisheye"},
                                    {"track": "lake", "world_seed": 3}, {"law": {"speed_limit_kmh": 0}},
                                    {"law": {"speed_limit_kmh": float("nan")}}, {"law": {"tau": "1"}},
                                    {"law": {"speed": 5}}, {"law": 25.0}, {"speed_limit_kmh": 5.0},
                                    {"max_episode_steps": 0}, {"no_such": 1}, {"action_delay": 2}])
def test_bad_arguments_are_one_clear_error(kwargs):
    with pytest.raises(BadValue):
        DriveEnv(**kwargs)


def test_the_control_law_is_one_argument_shared_with_drive_server():
    """Issue 51: speed_limit_kmh, steer_limit_deg and tau were copies of drive_server's ControlLaw's fields."""
    from dataclasses import fields

    from drive_server.serving.control import ControlLaw
    from tools.envs.config import DriveEnvConfig

    assert not {f.name for f in fields(ControlLaw)} & {f.name for f in fields(DriveEnvConfig)}
    law = ControlLaw(speed_limit_kmh=12.0, tau=0.5)
    assert DriveEnvConfig(law={"speed_limit_kmh": 12.0, "tau": 0.5}).law == law
    assert DriveEnvConfig(law=law).law is law
    with pytest.raises(BadValue, match="unknown law option.*: speed$") as exc:
        DriveEnvConfig(law={"speed_limit_kmh": 12.0, "speed": 1})
    assert "known: speed_limit_kmh" in exc.value.hint
    from tools.envs.config import config_from_kwargs

    with pytest.raises(BadValue) as exc:
        config_from_kwargs({"speed_limit_kmh": 12.0})
    assert "law={'speed_limit_kmh': ...}" in exc.value.hint


def test_bad_actions_are_refused(lake: DriveEnv):
    lake.reset(seed=0)
    for action in ([np.nan], [0.1, 0.2], "left"):
        with pytest.raises((BadValue, ValueError)):
            lake.step(action)


def test_action_delay_applies_each_action_one_step_late():
    now, late = DriveEnv(track="lake", jpeg=False), DriveEnv(track="lake", jpeg=False, action_delay=1)
    actions = [[0.0]] * 20 + [[-0.6]] * 10
    for env in (now, late):
        env.reset(seed=5)
    heading = {}
    for name, env in (("now", now), ("late", late)):
        for a in actions:
            _, _, _, _, info = env.step(a)
        heading[name] = info["heading_error_deg"]
    assert heading["now"] > heading["late"] > 0  # both turned left; the late one a step less


def test_vector_environments_sync_and_make_vec():
    envs = gym.vector.SyncVectorEnv([lambda: gym.make(ENV_ID, track="lake", jpeg=False)] * 2)
    obs, infos = envs.reset(seed=[1, 2])
    assert obs.shape == (2, 160, 320, 3) and infos["expert_action"].shape == (2, 1)
    for _ in range(5):
        obs, rewards, terminated, truncated, infos = envs.step(infos["expert_action"])
    assert rewards.shape == (2,) and not terminated.any()
    envs.close()
    vec = gym.make_vec("tools.envs:rbc/Drive-v0", num_envs=2, vectorization_mode="sync", track="lake", jpeg=False)
    obs, infos = vec.reset(seed=0)
    obs, rewards, *_ = vec.step(vec.action_space.sample() * 0)
    assert obs.shape == (2, 160, 320, 3) and rewards.shape == (2,)
    vec.close()


@pytest.mark.skipif(sys.platform != "linux", reason="forked workers share the parent's built world only on Linux")
def test_async_vector_environment_gives_the_sync_episodes():
    DriveEnv(track="lake").reset(seed=0)  # the world is built once here; forked workers inherit it
    make = [lambda: gym.make(ENV_ID, track="lake", jpeg=False)] * 2
    results = []
    for envs in (gym.vector.AsyncVectorEnv(make, context="fork"), gym.vector.SyncVectorEnv(make)):
        obs, infos = envs.reset(seed=[1, 2])
        for _ in range(5):
            obs, rewards, _, _, infos = envs.step(infos["expert_action"])
        results.append((obs, rewards))
        envs.close()
    assert np.array_equal(results[0][0], results[1][0]) and np.array_equal(results[0][1], results[1][1])


def test_onnx_policy_drives_lake_through_drive_servers_pipeline():
    policy = OnnxPolicy(PRETRAINED / "generalist_pilotnet.onnx")
    env = DriveEnv(track="lake", camera=policy.camera_rig)
    obs, info = env.reset(seed=0)
    # the first frame: the same steering drive_server computes from the telemetry carrying this JPEG
    telemetry = Telemetry(0.0, 0.0, 0.0, base64.b64encode(info["jpeg"]).decode("ascii"))
    fresh = DrivePipeline(SteeringModel(PRETRAINED / "generalist_pilotnet.onnx"))
    command, _ = fresh.run(telemetry, fresh.smoother())
    assert policy(obs, info)[0] == pytest.approx(command.steering, abs=1e-6)
    total = 0.0
    for _ in range(400):
        obs, reward, terminated, truncated, info = env.step(policy(obs, info))
        total += reward
        assert not terminated and not truncated
    assert info["progress_m"] > 150 and total > 140 and abs(info["cte_m"]) < 1.0


def test_without_terminate_on_takeover_the_episode_goes_on_from_where_the_car_was_put_back():
    env = DriveEnv(track="lake", jpeg=False, terminate_on_takeover=False, reward=RewardConfig(takeover=7.0))
    obs, info = env.reset(seed=0)
    for _ in range(400):
        obs, reward, terminated, truncated, info = env.step([-0.5])  # half lock left: off the road, as above
        assert not terminated and not truncated
        if info["intervention"]:
            break
    assert info["intervention"] == "off_road" and reward < -6.0  # the penalty, but no end
    assert abs(info["cte_m"]) < 0.5 and abs(info["heading_error_deg"]) < 1.0  # back on the line, aligned
    taken_at = info["step"]
    for _ in range(30):  # the expert drives on from there
        obs, reward, terminated, truncated, info = env.step(info["expert_action"])
        assert not terminated and info["intervention"] == ""
    assert info["step"] == taken_at + 30 and reward > 0 and abs(info["cte_m"]) < 0.5


def test_the_expert_label_is_the_new_observations_at_sb3s_auto_reset():
    """Was: SB3's VecEnv resets right after the terminal step and returns the new episode's first observation
    with the terminal step's info, whose expert_action labelled the terminal state (one frame stale)."""
    pytest.importorskip("stable_baselines3", reason="SB3's VecEnv needs pip install -e '.[rl]'")
    from stable_baselines3.common.vec_env import DummyVecEnv

    reference = DriveEnv(track="lake", jpeg=False, max_episode_steps=3)
    _, info = reference.reset(seed=4)
    for _ in range(3):
        _, _, _, truncated, terminal_info = reference.step(info["expert_action"])
    assert truncated
    vec = DummyVecEnv([lambda: gym.make(ENV_ID, track="lake", jpeg=False, max_episode_steps=3)])
    vec.seed(4)
    obs = vec.reset()
    assert np.array_equal(vec.reset_infos[0]["expert_action"], vec.env_method("expert_action")[0])
    label = vec.reset_infos[0]["expert_action"]
    for _ in range(3):
        obs, _, dones, infos = vec.step(np.stack([label]))
        label = infos[0]["expert_action"]
    assert dones[0] and not np.array_equal(obs[0], infos[0]["terminal_observation"])  # the new episode's frame
    fresh = vec.env_method("expert_action")[0]  # the autopilot's action for the state now observed
    assert abs(fresh[0] - terminal_info["expert_action"][0]) > 0.01  # the two states' labels differ
    assert np.array_equal(infos[0]["expert_action"], fresh)  # the label of the observation returned with it
    assert np.array_equal(vec.reset_infos[0]["expert_action"], fresh)
    assert infos[0]["terminal_expert_action"] == pytest.approx(terminal_info["expert_action"], abs=1e-5)
    vec.close()


def test_a_manual_reset_leaves_the_terminal_steps_info_as_it_was():
    env = DriveEnv(track="lake", jpeg=False, max_episode_steps=2)
    _, info = env.reset(seed=0)
    for _ in range(2):
        _, _, _, truncated, info = env.step(info["expert_action"])
    label = info["expert_action"].copy()
    _, fresh = env.reset()
    assert truncated and np.array_equal(info["expert_action"], label) and "terminal_expert_action" not in info
    assert np.array_equal(fresh["expert_action"], env.expert_action())


def test_the_expert_policy_predicts_the_labels_of_the_bound_envs_across_auto_resets():
    pytest.importorskip("stable_baselines3", reason="SB3's VecEnv needs pip install -e '.[rl]'")
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.policies import BasePolicy
    from stable_baselines3.common.vec_env import DummyVecEnv

    from tools.envs import ExpertPolicy

    vec = DummyVecEnv([lambda: gym.make(ENV_ID, track="lake", jpeg=False, max_episode_steps=4)] * 2)
    expert = ExpertPolicy(vec)
    vec.seed(2)
    obs = vec.reset()
    resets = 0
    for _ in range(6):  # one auto-reset in each env
        actions, state = expert.predict(obs, deterministic=True)
        assert state is None and actions.shape == (2, 1)
        obs, _, dones, infos = vec.step(actions)
        resets += int(dones.sum())
        assert np.array_equal(expert.predict(obs)[0], np.stack([i["expert_action"] for i in infos]))
    assert resets == 2
    policy = expert.sb3()  # imitation's DAgger wants an SB3 policy
    assert isinstance(policy, BasePolicy) and policy.observation_space == vec.observation_space
    assert np.array_equal(policy.predict(obs, deterministic=True)[0], expert(obs, None, None)[0])
    with pytest.raises(BadValue, match="2 bound environment"):
        expert.predict(obs[:1])
    vec.close()
    single = gym.make(ENV_ID, track="lake", jpeg=False, max_episode_steps=30)
    obs, info = single.reset(seed=0)
    action, _ = ExpertPolicy(single).predict(obs)
    assert action.shape == (1,) and np.array_equal(action, info["expert_action"])
    rewards, lengths = evaluate_policy(ExpertPolicy(single), single, n_eval_episodes=1, warn=False,
                                       return_episode_rewards=True)
    assert lengths == [30] and 3 < rewards[0] < 7  # no take-over; 2 s from standstill: the metres driven


def test_the_expert_policy_binds_gymnasium_vector_envs_and_refuses_others():
    from tools.envs import ExpertPolicy

    envs = gym.vector.SyncVectorEnv([lambda: gym.make(ENV_ID, track="lake", jpeg=False)] * 2)
    expert = ExpertPolicy(envs)
    obs, infos = envs.reset(seed=[1, 2])
    for _ in range(3):
        actions, _ = expert.predict(obs)
        assert np.array_equal(actions, infos["expert_action"])
        obs, _, _, _, infos = envs.step(actions)
    envs.close()
    with pytest.raises(BadValue, match="rbc/Drive-v0"):
        ExpertPolicy(gym.make("CartPole-v1"))
    with pytest.raises(BadValue):
        ExpertPolicy(object())  # type: ignore[arg-type]


def test_the_pages_expert_policy_example_runs(capsys):
    """docs/python.md's ExpertPolicy example, verbatim."""
    pytest.importorskip("stable_baselines3", reason="the example needs pip install -e '.[rl]'")
    import textwrap

    page = (REPO / "docs" / "python.md").read_text(encoding="utf-8")
    section = page[page.index("## The autopilot as a policy"):]
    example = section[section.index("```python\n") + 10:section.index("```\n", section.index("```python"))]
    exec(compile(textwrap.dedent(example), "docs/python.md", "exec"), {})
    metres = float(capsys.readouterr().out.split()[0])
    assert 40 < metres < 80  # 150 steps from standstill towards 25 km/h, no take-over


def _reports(env: DriveEnv) -> list:
    """The simulator's StepReport of every step of ``env`` from now on."""
    reports, step = [], env.client.step

    def recording(command, frames):
        reports.append(step(command, frames))
        return reports[-1]

    env.client.step = recording
    return reports


def test_the_default_reward_is_the_progress_less_the_lane_and_take_over_costs_exactly():
    env = DriveEnv(track="lake", jpeg=False)
    assert env.config.reward == RewardConfig()
    reports = _reports(env)
    _, info = env.reset(seed=0)
    rewards = []
    for _ in range(400):
        _, reward, terminated, _, info = env.step([-0.5])  # out of the lane, then off the road
        rewards.append(reward)
        if terminated:
            break
    assert info["intervention"] == "off_road" and any(r.out_of_lane_s for r in reports)
    for reward, r in zip(rewards, reports, strict=True):  # the reward as it always was, to the last bit
        assert reward == 1.0 * r.progress_m - 2.5 * r.out_of_lane_s - (10.0 if r.intervention else 0.0)


def test_reward_options_as_keywords_donkeycars_lane_term():
    env = gym.make(ENV_ID, track="lake", jpeg=False, reward={"progress_per_m": 0, "out_of_lane_per_s": 0,
                                                             "takeover": 0, "lane_per_m": 1.0, "max_cte_m": 2.0})
    assert env.unwrapped.config.reward == RewardConfig(progress_per_m=0, out_of_lane_per_s=0, takeover=0,
                                                       lane_per_m=1.0, max_cte_m=2.0)
    _, info = env.reset(seed=0)
    step_s = 1 / env.unwrapped.config.control_hz
    checked = {"inside": 0, "beyond": 0}
    for _ in range(400):
        before = info
        _, reward, terminated, _, info = env.step([-0.5])
        if terminated:
            break
        cte, speed = (before["cte_m"] + info["cte_m"]) / 2, (before["speed_kmh"] + info["speed_kmh"]) / 7.2
        expected = (1 - abs(cte) / 2.0) * speed * step_s  # gym-donkeycar's (1 - |cte| / max_cte) * speed
        if speed > 2.0:
            assert reward == pytest.approx(expected, abs=0.02), (cte, speed)
            checked["inside" if abs(cte) < 2.0 else "beyond"] += 1
    assert checked["inside"] > 10 and checked["beyond"] > 3  # beyond max_cte the term is a cost
    speed_only = DriveEnv(track="lake", jpeg=False, reward=RewardConfig(progress_per_m=0, speed_per_m=2.0))
    _, info = speed_only.reset(seed=0)
    total = 0.0
    for _ in range(60):
        _, reward, _, _, info = speed_only.step(info["expert_action"])
        total += reward
    assert total == pytest.approx(2.0 * info["progress_m"], rel=0.02)  # on the line: metres driven = progress


@pytest.mark.parametrize("reward", [{"lane": 1.0}, {"max_cte_m": 0}, {"takeover": float("nan")}, 3.0])
def test_bad_reward_options_are_one_clear_error(reward):
    with pytest.raises(BadValue, match="reward"):
        gym.make(ENV_ID, track="lake", reward=reward)


def test_the_pages_reward_options_run_in_python_and_as_an_rl_zoo_yaml():
    """docs/python.md's reward examples, verbatim: the Python one and the rl-zoo YAML's env_kwargs."""
    yaml = pytest.importorskip("yaml")
    page = (REPO / "docs" / "python.md").read_text(encoding="utf-8")
    section = page[page.index("### Reward options"):]
    python = section[section.index("```python\n") + 10:section.index("```\n", section.index("```python"))]
    scope: dict = {}
    exec(compile(python, "docs/python.md", "exec"), scope)
    kwargs = yaml.safe_load(section[section.index("```yaml\n") + 8:section.index("```\n", section.index("```yaml"))])
    from_yaml = gym.make(ENV_ID, **kwargs["rbc/Drive-v0"]["env_kwargs"])
    assert from_yaml.unwrapped.config == scope["env"].unwrapped.config
    assert scope["env"].unwrapped.config.reward == RewardConfig(progress_per_m=0.0, lane_per_m=1.0)


def test_a_bad_track_name_fails_at_make():
    """Was: make passed and reset raised a traceback from the simulator."""
    with pytest.raises(BadValue, match="nolake: no such track file"):
        gym.make(ENV_ID, track="nolake")


def test_step_after_close_or_before_reset_says_so():
    """Was: RuntimeError "HeadlessSimClient.start() was not called" for both."""
    env = DriveEnv(track="lake", jpeg=False)
    with pytest.raises(gym.error.ResetNeeded, match=r"reset\(\)"):
        env.step([0.0])
    env.reset(seed=0)
    env.step([0.0])
    env.close()
    with pytest.raises(gym.error.ClosedEnvironmentError, match="closed") as exc:
        env.step([0.0])
    assert isinstance(exc.value, BadValue) and "\n" not in str(exc.value)
    env.reset(seed=0)  # a closed environment opens again on reset, as Gymnasium's own do
    env.step([0.0])


def test_human_render_mode_needs_pygame_and_says_so_at_make(monkeypatch, tmp_path):
    """Was: gym.make applied gymnasium's HumanRendering and the first reset failed on the pygame import."""
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pygame" else real(name, *a))
    with pytest.raises(BadValue, match="pygame") as exc:
        gym.make(ENV_ID, track="lake", render_mode="human")
    assert "pip install pygame" in exc.value.hint
    monkeypatch.undo()
    (tmp_path / "pygame.py").write_text("")  # present (the window opens on the first frame: not here)
    monkeypatch.syspath_prepend(str(tmp_path))
    env = gym.make(ENV_ID, track="lake", render_mode="human")
    assert env.render_mode == "human" and isinstance(env.unwrapped, DriveEnv)
    assert env.unwrapped.render_mode == "rgb_array"  # gymnasium's HumanRendering shows its frames


def test_the_pages_keyword_list_names_every_argument():
    from dataclasses import fields

    from tools.envs import DriveEnvConfig

    page = (REPO / "docs" / "python.md").read_text(encoding="utf-8")
    keywords = page[page.index("Keyword arguments of `gym.make`"):page.index("### Reward options")]
    missing = [f.name for f in fields(DriveEnvConfig) if f"`{f.name}`" not in keywords]
    assert missing == [] and "`render_mode`" in keywords


def test_the_env_scores_each_observation_with_a_models_monitor(tmp_path):
    """monitor=PATH: info["monitor"] holds the score, one-second mean and state of every observation, as
    drive_server --monitor warn computes them; a file without a monitor is one line at make."""
    import gymnasium as gym
    from helpers_server import build_shallow
    from test_monitor import _brightness_graph, _with_monitor

    from drive_server.serving.monitor import MonitorSpec
    from protocol.errors import UserError

    plain = build_shallow(tmp_path / "m.onnx")
    model = _with_monitor(plain, tmp_path / "mon.onnx", MonitorSpec("brightness", -0.5, 0.45, 15),
                          _brightness_graph())
    env = gym.make("rbc/Drive-v0", monitor=str(model), max_episode_steps=20)
    _, first = env.reset(seed=1)
    assert first["monitor"]["state"] == "warning" and -0.5 < first["monitor"]["score"] < 0.5
    _, _, _, _, info = env.step(np.zeros(1, np.float32))
    both = (first["monitor"]["score"] + info["monitor"]["score"]) / 2  # the window's mean after two frames
    assert info["monitor"]["mean"] == pytest.approx(both)
    _, again = env.reset(seed=1)
    assert again["monitor"]["mean"] == pytest.approx(first["monitor"]["score"])  # each episode starts afresh
    env.close()
    with pytest.raises(UserError, match="carries no misbehaviour monitor"):
        gym.make("rbc/Drive-v0", monitor=str(plain))
