"""rbc/Drive-v0's domain randomisation (a new world, sun, light and fog per episode, training worlds only) and
its observation options (the model's own input, a Dict with the speed)."""

from __future__ import annotations

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")

from protocol.errors import BadValue  # noqa: E402
from tools.envs import ENV_ID, DriveEnv, WorldDistribution  # noqa: E402
from tools.envs.reset_options import check_reset_options  # noqa: E402

#: three small training worlds (their files are generated once per machine), drawn without light or fog
POOL = {"seeds": (0, 2), "pool": 2, "new_world_steps": 30}


def _episode(env, steps: int = 15, **reset):
    obs, info = env.reset(**reset)
    frames = [obs]
    for _ in range(steps):
        obs, _, _, _, info = env.step(info["expert_action"])
        frames.append(obs)
    return info, frames


def test_the_same_seed_draws_the_same_world_light_fog_and_spawn_and_the_same_episode():
    env = DriveEnv(worlds=POOL, spawn="random", jpeg=False)
    first, frames_a = _episode(env, seed=7)
    again, frames_b = _episode(env, seed=7)
    for key in ("world", "light_intensity", "fog", "sun_deg", "progress_m", "cte_m"):
        assert first[key] == again[key], key
    assert all(np.array_equal(a, b) for a, b in zip(frames_a, frames_b, strict=True))
    assert first["world"] in ("world:0", "world:1", "world:2")
    assert 0.4 <= first["light_intensity"] <= 2.5 and 0.5 <= first["fog"] <= 2.0
    # the episodes after a seeded reset: the same sequence on a fresh environment, with or without prefetching
    sequences = []
    for prefetch in (True, False):
        fresh = DriveEnv(worlds={**POOL, "prefetch": prefetch}, spawn="random", jpeg=False)
        sequences.append([(i["world"], i["light_intensity"], i["fog"]) for i in _episodes(fresh, 5, seed=7)])
    assert sequences[0] == sequences[1] and sequences[0][0] == (first["world"], first["light_intensity"], first["fog"])
    assert len({w for w, _, _ in sequences[0]}) > 1 and len({light for _, light, _ in sequences[0]}) == 5


def _episodes(env, count: int, steps: int = 10, seed: int = 1) -> list[dict]:
    """The first infos of ``count`` episodes of ``steps`` autopilot steps each, after ``reset(seed=seed)``."""
    _, info = env.reset(seed=seed)
    infos = [info]
    for _ in range(count - 1):
        for _ in range(steps):
            _, _, _, _, info = env.step(info["expert_action"])
        _, info = env.reset()
        infos.append(info)
    return infos


def test_a_rotating_pool_of_worlds_and_light_and_fog_every_episode():
    env = DriveEnv(worlds={"seeds": (0, 2), "pool": 1, "new_world_steps": 20}, jpeg=False)
    worlds = [i["world"] for i in _episodes(env, 6)]  # 10 steps an episode: a new world every second one
    assert worlds[0] == worlds[1] and worlds[2] == worlds[3] and worlds[4] == worlds[5]
    infos = _episodes(env, 6)
    assert len({i["light_intensity"] for i in infos}) == 6 and len({i["fog"] for i in infos}) == 6
    rotating = DriveEnv(worlds={"seeds": (0, 999), "pool": 2, "new_world_steps": 25, "prefetch": False},
                        jpeg=False)
    _, info = rotating.reset(seed=5)
    pools = [list(rotating.rotation.pool)]
    for episode in range(1, 8):
        for _ in range(10):
            _, _, _, _, info = rotating.step(info["expert_action"])
        _, info = rotating.reset()
        pool = rotating.rotation.pool
        assert len(pool) == 2 and info["world"] in [w for w, _ in pool]
        if episode in (3, 6):  # 30 steps >= 25: the oldest leaves, a new one comes in and is driven at once
            assert pool[0] == pools[-1][1] and info["world"] == pool[1][0] and pool[1] not in pools[-1]
        else:
            assert pool == pools[-1]
        pools.append(list(pool))


def test_light_fog_and_the_world_can_be_pinned_per_episode_by_the_options():
    env = DriveEnv(worlds=POOL, jpeg=False)
    dark, _ = env.reset(seed=3, options={"world_seed": 1, "light_intensity": 0.3, "fog": 1.0})
    bright, _ = env.reset(seed=3, options={"world_seed": 1, "light_intensity": 2.0, "fog": 1.0})
    assert dark.mean() + 10 < bright.mean()  # the same view, darker
    _, info = env.reset(seed=3, options={"world_seed": 1, "light_intensity": 2.0, "fog": 4.0})
    assert info["world"] == "world:1" and info["fog"] == 4.0
    foggy, _ = env.reset(seed=3, options={"track": "world:1", "light_intensity": 2.0, "fog": 4.0})
    assert not np.array_equal(foggy, bright)  # thicker haze towards the horizon
    lake = DriveEnv(jpeg=False)  # without a distribution the options pin this episode only
    plain, info = lake.reset(seed=0)
    assert info["world"] == "lake" and info["light_intensity"] == 1.0
    dim, info = lake.reset(seed=0, options={"light_intensity": 0.5})
    assert info["light_intensity"] == 0.5 and dim.mean() < plain.mean()
    again, _ = lake.reset(seed=0)
    assert np.array_equal(again, plain)


def test_the_held_out_evaluation_worlds_are_refused_and_never_drawn():
    for seeds in ((999_990, 1_000_010), (1_000_000, 1_000_005), (2_000_000, 2_000_001)):
        with pytest.raises(BadValue, match="held-out worlds must never be trained on") as exc:
            DriveEnv(worlds={"seeds": seeds})
        assert "\n" not in str(exc.value)
    rng = np.random.default_rng(0)
    widest = WorldDistribution(seeds=(0, 999_999))  # the whole training range: its top is next to the eval range
    seeds = [int(widest.draw_world(rng)[0].split(":")[1]) for _ in range(20_000)]
    assert 0 <= min(seeds) < 1_000 and 999_000 < max(seeds) <= 999_999
    small = WorldDistribution(seeds=(0, 9), tracks=("lake", "mountain"))
    drawn = {small.draw_world(rng)[0] for _ in range(1_000)}
    assert drawn == {f"world:{s}" for s in range(10)} | {"lake", "mountain"}
    with pytest.raises(BadValue, match="held-out worlds must never be trained on"):
        check_reset_options({"world_seed": 1_000_000}, "train")
    with pytest.raises(BadValue, match="held-out"):
        check_reset_options({"track": "world:1500000"}, "train")
    assert check_reset_options({"world_seed": 1_000_000}, "eval") == {"track": "world:1000000"}
    with pytest.raises(BadValue, match="built-in track names"):
        WorldDistribution(tracks=("world:1000000",))


@pytest.mark.parametrize("options", [{"world": 3}, {"light_intensity": -1}, {"fog": 0}, {"sun_deg": 120},
                                     {"spawn_s": float("nan")}, {"world_seed": -1}, {"world_seed": 1.5},
                                     {"track": "world:1", "world_seed": 1}, {"themes": ["lava"]}, {"cone_seed": "a"},
                                     "lake"])
def test_bad_reset_options_are_one_line_errors_before_anything_changes(options):
    env = DriveEnv(track="lake", jpeg=False)
    _, before = env.reset(seed=0)
    with pytest.raises(BadValue) as exc:
        env.reset(seed=1, options=options)
    assert "\n" not in str(exc.value)
    env.step(before["expert_action"])  # the episode under way goes on


@pytest.mark.parametrize("worlds", [{"seeds": (5, 1)}, {"seeds": 3}, {"light": (0, 2)}, {"fog": (2, 1)},
                                    {"sun_deg": (100,)}, {"themes": ("lava",)}, {"new_world_steps": 0},
                                    {"pool": 0}, {"seed": 1}, {"seeds": None}, "all", {"prefetch": "yes"}])
def test_bad_distributions_are_one_line_errors_at_make(worlds):
    with pytest.raises(BadValue) as exc:
        gym.make(ENV_ID, worlds=worlds)
    assert "\n" not in str(exc.value)


def test_worlds_is_instead_of_a_track():
    with pytest.raises(BadValue, match="not both"):
        DriveEnv(track="lake", worlds=True)


def test_themes_restrict_the_generated_worlds():
    env = DriveEnv(worlds={"seeds": (0, 0), "themes": ["snow"], "light": None, "fog": None}, jpeg=False)
    env.reset(seed=0)
    assert env.client.sim.track.scenery.theme == "snow"
    assert env.worlds.get(env._episode.key).path.endswith("-snow.json")


# ------------------------------------------------------------------------------------------------ observations

def test_the_model_observation_is_what_drive_server_feeds_the_network():
    from drive_server.serving.model import SteeringModel
    from drive_server.serving.preprocess import frame_to_network_image, jpeg_reduction
    from protocol.jpeg import decode_jpeg
    from tools.envs.config import MODEL_CONTRACTS

    env = gym.make(ENV_ID, track="lake", observation="model")
    obs, info = env.reset(seed=2)
    contract = SteeringModel("models/pretrained/generalist.onnx").contract
    assert contract == MODEL_CONTRACTS["unity"] == env.unwrapped.config.contract
    assert obs.shape == (64, 64, 3) and obs.dtype == np.uint8 and env.observation_space.contains(obs)
    expected = frame_to_network_image(decode_jpeg(info["jpeg"], jpeg_reduction(contract)), contract)
    assert np.array_equal(obs, expected)
    paper = gym.make(ENV_ID, track="lake", observation="model", camera="classic", jpeg=False)
    obs, _ = paper.reset(seed=2)
    assert paper.unwrapped.config.contract == MODEL_CONTRACTS["classic"]
    assert np.array_equal(obs, frame_to_network_image(paper.unwrapped._frame, MODEL_CONTRACTS["classic"]))
    custom = DriveEnv(track="lake", observation="model", contract="models/pretrained/unity.onnx")
    assert custom.observation_space.shape == (64, 128, 3)


def test_a_dict_observation_with_the_speed_passes_both_checkers():
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ENV_ID, track="lake", observation="model", speed=True)
    obs, info = env.reset(seed=0)
    assert set(obs) == {"center", "speed"} and obs["speed"].dtype == np.float32 and obs["speed"][0] == 0.0
    for _ in range(40):
        obs, _, _, _, info = env.step(info["expert_action"])
    assert obs["speed"][0] == pytest.approx(info["speed_kmh"], abs=0.01) and obs["speed"][0] > 5
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_check_env(env.unwrapped, warn=True)


@pytest.mark.parametrize("kwargs", [{"observation": "pixels"}, {"speed": 1}, {"contract": {"width": 64}},
                                    {"observation": "model", "contract": {"size": 64}},
                                    {"observation": "model", "contract": 64}])
def test_bad_observation_options_are_one_line_errors(kwargs):
    with pytest.raises(BadValue) as exc:
        DriveEnv(track="lake", **kwargs)
    assert "\n" not in str(exc.value)


@pytest.mark.skipif(__import__("sys").platform != "linux", reason="fork-started workers are Linux's")
def test_async_and_sync_vector_envs_draw_the_same_worlds_and_episodes():
    """Forked workers inherit the parent's built worlds while its background build may be running: they start
    without its threads and locks, and draw what the same environments draw in one process."""
    DriveEnv(worlds=POOL, jpeg=False).reset(seed=0)  # a background build under way in the parent
    make = [lambda: gym.make(ENV_ID, worlds=POOL, jpeg=False, max_episode_steps=12)] * 2
    results = []
    for envs in (gym.vector.AsyncVectorEnv(make, context="fork"), gym.vector.SyncVectorEnv(make)):
        obs, infos = envs.reset(seed=[1, 2])
        worlds = [tuple(infos["world"])]
        for _ in range(40):  # three episodes each, a new world after 30 steps
            obs, _, _, _, infos = envs.step(infos["expert_action"])
            worlds.append(tuple(infos["world"]))
        results.append((obs, worlds))
        envs.close()
    assert np.array_equal(results[0][0], results[1][0]) and results[0][1] == results[1][1]
    assert len(set(results[0][1])) > 1
