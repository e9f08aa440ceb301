"""rbc dagger (tools.dagger): rounds that aggregate expert-labelled frames, beta's decay, resume, the records."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")
pytest.importorskip("torch", reason="the train extra is not installed")

from protocol.datalog_writer import LOG_NAME  # noqa: E402
from protocol.errors import BadValue  # noqa: E402
from protocol.runrecords import file_sha256, read_json  # noqa: E402
from tools.dagger import loop, rollout, summary  # noqa: E402
from tools.dagger.config import DaggerConfig, budgets_from  # noqa: E402
from tools.dagger.report import comparison_table, frames_to_target, plot_curve, verdict  # noqa: E402

pytestmark = pytest.mark.slow

TINY_WORLDS = {"min_length_m": 200, "max_length_m": 400, "drive_check": False}  # 0.2-0.4 km evaluation loops
CLI = ["dagger", "--budgets", "60,120", "--episode-steps", "60", "--epochs", "1", "--max-steps-per-epoch", "2",
       "--eval-worlds", "2", "--eval-world-config", json.dumps(TINY_WORLDS), "--tracks", "--seed", "3",
       "--threads", "1", "--no-progress"]


def _config(**changes) -> DaggerConfig:
    """The settings the CLI line above asks for."""
    base = dict(budgets=(60, 120), episode_steps=60, epochs=1, max_steps_per_epoch=2, eval_worlds=2,
                eval_world_config=TINY_WORLDS, tracks=(), seed=3)
    return DaggerConfig(**{**base, **changes})


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    """A clean two-round DAgger run through the command line, as the docs run it."""
    from tools.cli import main

    out = tmp_path_factory.mktemp("dagger") / "clean"
    assert main([*CLI, "--out", str(out)]) == 0
    return out


def _log(folder: Path) -> list[list[str]]:
    with (folder / LOG_NAME).open(newline="", encoding="utf-8") as fh:
        return [[c.strip() for c in row] for row in csv.reader(fh)]


def _frames(folder: Path) -> list[dict[str, str]]:
    with (folder / rollout.FRAMES_CSV).open(newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_beta_decays_and_round_zero_is_the_experts():
    config = DaggerConfig(budgets=(1000, 2000, 4000, 8000), beta0=1.0, beta_decay=0.5)
    assert [config.beta(r) for r in range(4)] == [1.0, 0.5, 0.25, 0.125]
    assert [config.new_frames(r) for r in range(4)] == [1000, 1000, 2000, 4000]
    assert [DaggerConfig(beta0=0.8, beta_decay=0.5).beta(r) for r in range(3)] == [1.0, 0.4, 0.2]
    assert all(DaggerConfig(mode="bc").beta(r) == 1.0 for r in range(4))
    assert budgets_from(3, 500) == (500, 1000, 1500)


@pytest.mark.parametrize("changes", [{"budgets": (100, 100)}, {"budgets": ()}, {"beta0": 1.5}, {"beta_decay": -0.1},
                                     {"mode": "gail"}, {"eval_world_seed": 5}, {"eval_worlds": 0, "tracks": ()},
                                     {"cameras": 2}, {"eval_world_config": {"nope": 1}}])
def test_bad_settings_are_one_clear_error(changes):
    with pytest.raises(BadValue):
        DaggerConfig(**changes)


def test_evaluation_worlds_are_refused_for_training_data(tmp_path, monkeypatch):
    config = _config()
    train_worlds = [e.world_seed for r in range(3) for e in rollout.episodes(config, r, 50)]
    assert all(0 <= s < 1_000_000 for s in train_worlds) and not set(train_worlds) & set(config.eval_seeds())
    # were an episode ever drawn on an evaluation world, the environment (purpose "train") refuses it
    monkeypatch.setattr(rollout, "episodes", lambda *a: [rollout.Episode(config.eval_seeds()[0], 1)])
    with pytest.raises(BadValue, match="held-out worlds must never be trained on"):
        rollout.collect_round(config, 0, tmp_path / "data", None)
    assert not (tmp_path / "data").exists()


def test_every_visited_frame_is_labelled_by_the_expert(clean):
    config = _config()
    for r, beta in ((0, 1.0), (1, 0.5)):
        data = clean / f"round-{r:02d}" / "data"
        rows, frames = _log(data), _frames(data)
        assert len(rows) == len(frames) == config.new_frames(r) == 60
        assert all(Path(row[0]).is_file() for row in rows) and read_json(data / "camera_rig.json")["rig"] == "unity"
        # the log's label is the expert's steering for the frame, whoever drove
        assert [float(row[3]) for row in rows] == pytest.approx([float(f["expert_steering"]) for f in frames], abs=1e-6)
        drivers = {f["driver"] for f in frames}
        if beta == 1.0:
            assert drivers == {"expert"} and all(f["learner_steering"] == "" for f in frames)
        else:  # the learner drove about half the steps and was asked every step
            assert drivers == {"expert", "learner"} and all(f["learner_steering"] for f in frames)
            learner = [f for f in frames if f["driver"] == "learner"]
            assert 15 <= len(learner) <= 45
        stats = read_json(data / rollout.SUMMARY)
        assert stats["frames"] == 60 and stats["learner_steps"] == sum(f["driver"] == "learner" for f in frames)
    # the first label is what the environment's expert says for that state (the same world and reset seed)
    from tools.envs import DriveEnv

    first = rollout.episodes(config, 0, 1)[0]
    env = DriveEnv(world_seed=first.world_seed, spawn="random", action_delay=1, law={"speed_limit_kmh": 25.0})
    _, info = env.reset(seed=first.reset_seed)
    assert float(_log(clean / "round-00" / "data")[0][3]) == pytest.approx(float(info["expert_action"][0]), abs=1e-6)


def test_who_drives_is_one_draw_a_step_from_the_rounds_mixing_stream(clean):
    """The wrapper (tools.dagger.mixing) decides with the round's own stream, [seed, round, STREAM_MIX], one draw a
    step across the round's episodes: the same decisions for the same seed."""
    from tools.dagger.config import STREAM_MIX

    config = _config()
    drivers = [f["driver"] for f in _frames(clean / "round-01" / "data")]
    draws = np.random.default_rng([config.seed, 1, STREAM_MIX]).random(len(drivers))
    assert drivers == ["expert" if d < config.beta(1) else "learner" for d in draws]


def test_each_round_trains_on_the_aggregate_and_records_it(clean):
    config = _config()
    train = read_json(clean / "round-01" / "train" / "config.json")
    assert [Path(d).parent.name for d in train["config"]["data"]] == ["round-00", "round-01"]
    assert train["config"]["seed"] == 3 and train["config"]["epochs"] == 1
    for r in range(2):
        record = read_json(clean / f"round-{r:02d}" / "record.json")
        assert record["round"] == r and record["expert_frames"] == config.budgets[r]
        assert record["seed"] == 3 and record["config"] == config.to_dict() and record["code_version"]
        assert record["beta"] == config.beta(r) and record["mode"] == "dagger"
        assert record["model_sha256"] == file_sha256(clean / record["model"])
        worlds = record["eval"]["worlds"]
        assert [w["seed"] for w in worlds["per_world"]] == [1_000_000, 1_000_001] and worlds["n"] == 2
        assert worlds["worst"]["eta"] == min(w["eta"] for w in worlds["per_world"])
        assert record["eval"]["all"]["takeovers"] == worlds["takeovers"]
    assert read_json(clean / "round-01" / "record.json")["learner_sha256"] == file_sha256(loop.model_path(clean, 0))
    summary = read_json(clean / "summary.json")
    assert [row["expert_frames"] for row in summary["rounds"]] == [60, 120] and summary["seed"] == 3
    assert "| 1 | dagger | 0.5 | 120 |" in (clean / "rounds.md").read_text()


def test_a_killed_run_resumes_to_the_clean_runs_records(clean, tmp_path, monkeypatch):
    config, out = _config(), tmp_path / "killed"
    real_collect, real_eval = loop.collect_round, loop_evaluate()

    def collect_then_die(config, r, folder, learner, progress=None):
        if r == 0:
            return real_collect(config, r, folder, learner, progress)
        real_write, written = rollout._write_frames, []

        def write_then_die(*args):  # killed after round 1's 20th frame: a half-written data.partial is left
            if len(written) == 20:
                raise KeyboardInterrupt
            written.append(1)
            return real_write(*args)

        monkeypatch.setattr(rollout, "_write_frames", write_then_die)
        try:
            return real_collect(config, r, folder, learner, progress)
        finally:
            monkeypatch.setattr(rollout, "_write_frames", real_write)

    monkeypatch.setattr(loop, "collect_round", collect_then_die)
    with pytest.raises(KeyboardInterrupt):
        loop.run(config, out, threads=1, progress=False)
    assert (out / "round-00" / "record.json").is_file() and (out / "round-01" / "data.partial").is_dir()
    monkeypatch.setattr(loop, "collect_round", real_collect)

    def eval_dies(*args, **kwargs):  # killed again, after round 1's training, in its evaluation
        raise KeyboardInterrupt

    monkeypatch.setattr("tools.dagger.scoring.evaluate_model", eval_dies)
    with pytest.raises(KeyboardInterrupt):
        loop.run(config, out, resume=True, threads=1, progress=False)
    assert (out / "round-01" / "train" / "model.onnx").is_file() and not (out / "round-01" / "record.json").exists()
    monkeypatch.setattr("tools.dagger.scoring.evaluate_model", real_eval)
    with pytest.raises(BadValue, match="holds a DAgger run already"):
        loop.run(config, out, threads=1, progress=False)  # not without --resume
    with pytest.raises(BadValue, match="other settings"):
        loop.run(_config(seed=4), out, resume=True, threads=1, progress=False)
    records = loop.run(config, out, resume=True, threads=1, progress=False)
    for r, record in enumerate(records):
        assert loop.comparable(record) == loop.comparable(read_json(clean / f"round-{r:02d}" / "record.json"))
    assert _log(out / "round-01" / "data")[-1][3:] == _log(clean / "round-01" / "data")[-1][3:]
    assert not (out / "round-01" / "data.partial").exists()


def loop_evaluate():
    from tools.dagger import scoring

    return scoring.evaluate_model


def _rows(frames: list[int], mean: list[float], worst: list[float], at: list[int], mode: str) -> list[dict]:
    return [{"round": i, "mode": mode, "beta": 1.0, "expert_frames": f, "worlds_mean": m, "worlds_worst": w,
             "worlds_at_target": a, "worlds_n": 20, "worlds_takeovers": 20 - a, "lake_eta": 100.0, "lake_takeovers": 0,
             "mountain_eta": m, "mountain_takeovers": 1, "all_mean": m, "all_worst": w, "all_takeovers": 21 - a}
            for i, (f, m, w, a) in enumerate(zip(frames, mean, worst, at, strict=True))]


def test_the_verdict_compares_frames_to_target(tmp_path):
    bc = _rows([1000, 2000, 4000, 8000], [80, 85, 92, 98], [40, 60, 85, 96], [5, 10, 15, 20], "bc")
    dagger = _rows([1000, 2000, 4000], [80, 97, 99], [40, 96, 97], [5, 20, 20], "dagger")
    assert frames_to_target(bc) == 8000 and frames_to_target(dagger) == 2000
    found = verdict(dagger, bc)
    assert found["met"] and found["ratio"] == 0.25 and "met" in found["text"]
    slow = verdict(_rows([4000], [99], [97], [20], "dagger"), bc)
    assert not slow["met"] and slow["ratio"] == 0.5
    never = verdict(dagger, bc[:2])  # BC never got there within 2000 frames: a third of that is not reached
    assert not never["bc_reached"] and not never["met"] and "never within 2,000" in never["text"]
    missed = verdict(dagger[:1], bc)
    assert not missed["met"] and missed["dagger_best"]["worlds_at_target"] == 5 and missed["text"].startswith("missed")
    table = comparison_table(dagger, bc)
    assert "| 2,000 | BC | 85.0 % | 60.0 % | 10/20 | 11 | 100.0 % | 85.0 % |" in table
    assert "| 2,000 | DAgger (expert only) | 97.0 % | 96.0 % | 20/20 | 1 | 100.0 % | 97.0 % |" in table
    assert plot_curve(dagger, bc, tmp_path / "curve.png").stat().st_size > 10_000


def test_the_label_is_smooth_pure_pursuit_not_keyboard_pulses(clean):
    labels = np.array([float(row[3]) for row in _log(clean / "round-00" / "data")])
    assert np.mean(labels == 0.0) < 0.2  # rbc collect's keyboard labels are ~70 % exact zeros


def test_the_docs_example_runs(capsys):
    """docs/python.md's ten lines: the learner drives, the expert's label beside each of its actions."""
    import re
    import textwrap

    page = (Path(__file__).resolve().parents[1] / "docs" / "python.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", page, flags=re.S)
    example = next(b for b in blocks if "the autopilot labels what it visits" in b)
    exec(compile(textwrap.dedent(example), "docs/python.md", "exec"), {})
    assert re.fullmatch(r"1500 frames, \d+ m, \d+ take-overs, mean \|learner - expert\| 0\.\d{3}\n",
                        capsys.readouterr().out)


def test_the_perturbations_are_rbc_evals_table9_rows(clean, tmp_path):
    """--perturbations: Table 9's orientation and light rows on lake, rbc eval's range searches, in the record."""
    from tests.conftest import write_stadium
    from tools.dagger.scoring import evaluate_model

    config = _config(eval_worlds=0, tracks=(write_stadium(tmp_path, straight=40.0, radius=25.0),), perturbations=True)
    scores = evaluate_model(loop.model_path(clean, 1), tmp_path / "eval", config, [])
    assert set(scores["perturbations"]) == {"orientation", "light_intensity", "light_direction"}
    for found in scores["perturbations"].values():  # a two-step model is taken over on lake: every range is empty
        assert found["text"] and {"lower", "upper", "unit"} <= set(found)
    assert scores["all"]["runs"] == 1 and "worlds" not in scores
    row = summary.round_row({"round": 0, "mode": "dagger", "beta": 1.0, "expert_frames": 60, "eval": scores,
                             "collection": {"learner_steps": 0, "takeovers": 0}})
    assert "orientation" in summary.rounds_table([row])


def test_the_recorded_clock_runs_at_the_environments_control_rate(tmp_path, monkeypatch):
    """Issue 51: the rollout advanced its clock by a hard-coded 15 Hz beside the environment's own control rate, so
    an environment at another rate recorded overlapping episodes."""
    import gymnasium

    from protocol.stamps import frame_time

    real_make = gymnasium.make
    monkeypatch.setattr(gymnasium, "make", lambda *a, **k: real_make(*a, control_hz=30.0, **k))
    config = _config(budgets=(20, 40), episode_steps=10)
    rollout.collect_round(config, 0, tmp_path / "data", None)
    times = [frame_time(row[0]) for row in _log(tmp_path / "data")]
    assert np.diff(times[:10]) == pytest.approx(1 / 30, abs=2e-3)  # steps of one episode: the environment's rate
    assert times[10] - times[0] == pytest.approx(10 / 30 + 10.0, abs=2e-3)  # the next episode after a 10 s pause
