"""python -m tools.dagger.rlcompare: PPO, ONNX models and the expert scored alike, by rbc eval's referee and eta."""

from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")

import tools.envs  # noqa: E402,F401  (registers rbc/Drive-v0)
from protocol import encode_telemetry  # noqa: E402
from protocol.units import from_kmh  # noqa: E402
from tools.dagger.rlcompare import main, score_policy  # noqa: E402
from tools.envs.config import config_from_kwargs  # noqa: E402
from tools.envs.policydrivers import ExpertDriver, PolicySpec, SB3Driver, ppo_env_config  # noqa: E402
from tools.evaluate.worlds import write_eval_worlds  # noqa: E402
from tools.sim.driving.drivers import Frame  # noqa: E402
from tools.sim.driving.rules import DEFAULT_RULES  # noqa: E402
from tools.sim.worldgen import WorldGenConfig  # noqa: E402

pytestmark = pytest.mark.slow

SHORT = {"min_length_m": 200, "max_length_m": 400, "drive_check": False}  # a 0.2-0.4 km evaluation loop
GENERALIST = Path("models/pretrained/generalist.onnx")
SEED = 1_000_000


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> str:
    out = tmp_path_factory.mktemp("worlds")
    return write_eval_worlds(out, [SEED], WorldGenConfig(**SHORT), resume=False)["files"][SEED]


class Constant:
    """A stub SB3 policy: the same action whatever it sees; remembers what it was shown."""

    def __init__(self, action: list[float]) -> None:
        self.action, self.seen = np.array(action, np.float32), []

    def predict(self, obs, deterministic=True):
        self.seen.append(obs)
        return self.action, None


def _records(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / "runs.jsonl").read_text(encoding="utf-8").splitlines()]


def test_an_onnx_model_scores_as_rbc_eval_scores_it(tmp_path, world):
    """The same world, the same model: rbc eval --experiments unseen_worlds and the comparison drive the same lap
    (every lap figure to the last digit), and the comparison's scores are its laps' eta and take-overs."""
    from tools.cli import main as rbc

    assert rbc(["eval", "--model", str(GENERALIST), "--experiments", "unseen_worlds", "--worlds", "1",
                "--world-config", json.dumps(SHORT), "--workers", "1", "--out", str(tmp_path / "eval")]) == 0
    scores = score_policy(PolicySpec("g", "onnx", str(GENERALIST)), tmp_path / "g", [(SEED, world)], [])
    ours, theirs = _records(tmp_path / "g"), _records(tmp_path / "eval")
    assert len(ours) == len(theirs) == 1
    assert ours[0]["laps"] == theirs[0]["laps"] and ours[0]["driver"] == theirs[0]["driver"]
    assert {k: v for k, v in ours[0]["scenario"].items() if k != "track"} == \
        {k: v for k, v in theirs[0]["scenario"].items() if k != "track"}
    lap = theirs[0]["laps"][0]
    assert scores["worlds"]["per_world"] == [{"seed": SEED, "eta": lap["eta"], "takeovers": lap["n_interventions"]}]


def test_eta_is_one_minus_six_seconds_per_takeover_over_the_lap_and_the_table_says_so(tmp_path, world):
    """A policy that steers right all lap is taken over again and again, put back and drives on to the lap's
    end; its eta is the paper's, 1 - take-overs x 6 s / lap time (clamped at 0), and the aggregate is its world's."""
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.session import run_scenario

    config = ppo_env_config(tmp_path)  # no recipe.json: the recipe's defaults
    driver = SB3Driver(Constant([0.3]), config, config.law)
    result = run_scenario(ScenarioConfig(track=world, seed=0, spawn_noise=True, camera=config.camera), driver)
    lap = result.laps[0]
    assert lap.completed and lap.n_interventions >= 2  # taken over and driven on
    expected = max(0.0, 1.0 - lap.n_interventions * DEFAULT_RULES.seconds_per_intervention / lap.lap_time_s) * 100
    assert DEFAULT_RULES.seconds_per_intervention == 6.0
    assert lap.eta == pytest.approx(expected) and 0.0 <= lap.eta < 100.0
    assert len(driver.policy.seen) == result.frames - 1  # every frame answered but the last in flight


def test_the_sb3_driver_sees_what_the_env_shows_and_commands_what_it_would(world):
    """The PPO policy drives the simulator's runs on the observation rbc/Drive-v0 trained it on: the same 64x64
    input and speed from the same JPEG and telemetry, and the same command for the same action."""
    camera = ppo_env_config(Path("no-such-run")).camera  # the recipe's
    env = gym.make("rbc/Drive-v0", track=world, purpose="eval", observation="model", speed=True, camera=camera)
    obs, info = env.reset(seed=3)
    for _ in range(12):
        obs, _, _, _, info = env.step(np.array([0.1], np.float32))
    denv = env.unwrapped
    state = denv.client._seen.state
    payload = encode_telemetry(math.degrees(state.steer), state.throttle, from_kmh(state.speed * 3.6, "mph"),
                               base64.b64encode(info["jpeg"]).decode("ascii"))
    config = config_from_kwargs({"observation": "model", "speed": True, "camera": camera})
    driver = SB3Driver(Constant([-0.4]), config, config.law)
    frame = Frame(payload=payload, t=0.0, truth=state)
    seen = driver.observation(frame)
    assert seen["center"].dtype == np.uint8 and seen["center"].shape == obs["center"].shape == (64, 64, 3)
    assert np.array_equal(seen["center"], obs["center"])
    assert seen["speed"] == pytest.approx(obs["speed"], abs=1e-4) and obs["speed"][0] > 5
    assert driver.steer(frame) == denv.command(np.array([-0.4], np.float32))
    expert = ExpertDriver(config.law)
    with pytest.raises(RuntimeError):
        expert.steer(frame)
    env.close()


def test_a_tiny_ppo_policy_and_the_expert_through_the_command(tmp_path, world, capsys):
    """An untrained PPO model.zip (SB3's, the recipe's network) and the expert on one short world: the record
    holds each world's eta and take-overs, the mean, the worst and the worlds at 95 %, and the table prints them."""
    pytest.importorskip("stable_baselines3", reason="the rl extra is not installed")
    import torch
    from stable_baselines3 import PPO

    from tools.envs.ppo import PPORecipe, small_cnn

    torch.set_num_threads(1)
    run = tmp_path / "ppo"
    run.mkdir()
    env = gym.make("rbc/Drive-v0", **PPORecipe().make_kwargs())
    PPO("MultiInputPolicy", env, n_steps=64, batch_size=32, seed=0, device="cpu",
        policy_kwargs={"features_extractor_class": small_cnn(), "net_arch": [64]}).save(run / "model.zip")
    env.close()
    out = tmp_path / "cmp"
    assert main(["--out", str(out), "--ppo", str(run), "--expert", "--worlds", "1", "--world-config",
                 json.dumps(SHORT), "--tracks", ""]) == 0
    record = json.loads((out / "comparison.json").read_text(encoding="utf-8"))
    assert record["seed"] == 0 and record["code_version"] and record["worlds"]["seeds"] == [SEED]
    assert [p["name"] for p in record["policies"]] == ["PPO", "expert"]
    for policy in record["policies"]:
        (run_record,) = _records(out / policy["name"])
        lap = run_record["laps"][0]
        assert run_record["value"] == SEED and run_record["scenario"]["seed"] == 0
        worlds = policy["worlds"]
        assert worlds["per_world"] == [{"seed": SEED, "eta": lap["eta"], "takeovers": lap["n_interventions"]}]
        assert worlds["mean"] == worlds["worst"]["eta"] == lap["eta"] and worlds["at_target"] == (lap["eta"] >= 95)
    expert = record["policies"][1]["worlds"]
    assert expert["takeovers"] == 0 and expert["mean"] == 100.0  # the expert drives the short world cleanly
    printed = capsys.readouterr().out
    assert "| PPO (ppo) |" in printed and "| expert (expert) | 100.0 % |" in printed
    # a second run reuses the journaled runs: the same record
    assert main(["--out", str(out), "--ppo", str(run), "--expert", "--worlds", "1", "--world-config",
                 json.dumps(SHORT), "--tracks", ""]) == 0
    again = json.loads((out / "comparison.json").read_text(encoding="utf-8"))
    assert again["policies"] == record["policies"]


@pytest.mark.parametrize("flags, says", [
    (["--onnx", "bc.onnx"], "give NAME=PATH"),
    (["--onnx", "bc=missing.onnx"], "no such file"),
    (["--expert", "--tracks", "nowhere"], "nowhere"),
    ([], "give each policy once"),
])
def test_a_bad_command_line_is_one_line(tmp_path, capsys, flags, says):
    assert main(["--out", str(tmp_path / "o"), "--worlds", "0", *flags]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1


def test_a_policy_spec_says_what_it_is(tmp_path):
    with pytest.raises(ValueError, match="kind"):
        PolicySpec("x", "bc", "m.onnx")
    with pytest.raises(ValueError, match="no file"):
        PolicySpec("x", "expert", "m.onnx")
    assert PolicySpec("x", "ppo", str(tmp_path)).model_file == tmp_path / "model.zip"
    assert PolicySpec("x", "onnx", "m.onnx").model_file == Path("m.onnx")
