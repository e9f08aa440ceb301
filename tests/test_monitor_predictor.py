"""#53: the failure predictor: labels from what followed each frame, run files, the run sets it may learn and
calibrate on (never a benchmark, calibration-of-the-benchmark or evaluation world), training, export and fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models.monitoring.failures import FailureRun, LabelRules, labels, load_run, quantise, run_files, save_run
from protocol.errors import BadValue

REPO = Path(__file__).resolve().parents[1]


def test_labels_positive_before_a_misbehaviour_negative_far_from_one_and_left_out_around_resets() -> None:
    t = np.arange(0, 30, 0.5)
    y = labels(t, [(15.0, "off_road"), (25.0, "stuck")], LabelRules(horizon_s=3.0, quiet_s=6.0, settle_s=4.0))
    at = dict(zip(t.tolist(), y.tolist(), strict=True))
    assert at[0.0] == at[3.5] == -1  # the start settles
    assert at[4.0] == at[8.5] == 0  # quiet: more than 6 s before the failure
    assert at[9.5] == at[11.5] == -1  # 3-6 s before it: left out
    assert at[12.5] == at[14.5] == 1  # within 3 s: positive
    assert at[15.0] == at[18.5] == -1  # the car was just put back
    assert at[20.0] == at[24.5] == 0  # a stuck take-over is not a misbehaviour to foresee
    assert at[25.0] == at[28.5] == -1


def test_a_run_file_round_trips_and_a_broken_one_is_one_line(tmp_path: Path) -> None:
    x = np.random.default_rng(0).random((5, 64, 64, 3), dtype=np.float32) - 0.5
    run = FailureRun("r", quantise(x), np.arange(5, dtype=np.float32) / 15, ((0.2, "off_road"),), {"group": "x"})
    save_run(tmp_path / "r.npz", run)
    back = load_run(tmp_path / "r.npz")
    assert back.takeovers == run.takeovers and back.meta["group"] == "x" and back.name == "r"
    assert np.abs(back.floats() - x).max() <= 0.5 / 255 + 1e-6
    (tmp_path / "bad.npz").write_bytes(b"nope")
    with pytest.raises(BadValue, match="not a failure run") as info:
        load_run(tmp_path / "bad.npz")
    assert "\n" not in str(info.value)
    with pytest.raises(BadValue, match="no failure runs"):
        run_files([tmp_path / "empty"])


def test_the_predictors_runs_never_touch_benchmark_calibration_or_evaluation_worlds() -> None:
    from tools.monitoreval.bench import EvalPlan
    from tools.monitoreval.calibruns import CALIBRATION_WORLDS, calibration_runs
    from tools.monitoreval.runset import (
        FAILURE_WORLDS,
        HELD_OUT_AXES,
        NOMINAL_WORLDS,
        UNSEEN_WORLDS_FIRST,
        failing_runs,
        failure_training_runs,
        nominal_runs,
    )

    train = failure_training_runs(6, 20)
    worlds = {int(s.track.split(":")[1]) for s in train}
    assert all(s.track.startswith("world:") for s in train)  # no built-in track: the benchmark drives lake
    assert worlds <= set(FAILURE_WORLDS) and len(worlds) > 50
    assert not worlds & (set(NOMINAL_WORLDS) | set(CALIBRATION_WORLDS)) and max(worlds) < UNSEEN_WORLDS_FIRST
    assert not {s.axis for s in train} & set(HELD_OUT_AXES)
    bench = {s.track for s in nominal_runs(EvalPlan.nominal) + failing_runs(EvalPlan.per_setting)}
    assert not bench & {s.track for s in train} and not bench & {s.track for s in calibration_runs(30)}
    assert {int(s.track.split(":")[1]) for s in calibration_runs(30)} == set(CALIBRATION_WORLDS)


def test_the_predictor_learns_a_visible_danger_and_its_onnx_graph_answers_as_torch_does() -> None:
    """A synthetic task: a bright band on one side of the picture precedes a failure. The exported graph takes
    the steering model's own input and answers one probability per frame."""
    from drive_server.serving.contract import PreprocessContract
    from models.monitoring.autoencoder import export_score_graph
    from models.monitoring.disagreement import graph_scores
    from models.monitoring.predictor import train_predictor

    rng = np.random.default_rng(0)
    x = rng.random((600, 64, 64, 3), dtype=np.float32) * 0.3 - 0.15
    y = (rng.random(600) < 0.2).astype(np.int8)
    x[y == 1, :, :12] += 0.3
    contract = PreprocessContract(width=64, height=64, color="rgb", layout="nhwc", crop_top=0, crop_bottom=160)
    model = train_predictor(quantise(x), y, contract, epochs=8, batch_size=32, seed=0)
    graph = export_score_graph(model, contract)
    p = graph_scores(graph, x)
    assert p.shape == (600,) and np.all((p >= 0) & (p <= 1))
    assert p[y == 1].mean() > 0.7 and p[y == 0].mean() < 0.3
    with pytest.raises(ValueError, match="both kinds"):
        train_predictor(quantise(x), np.zeros(600, np.int8), contract)


def test_fit_refuses_runs_on_evaluation_worlds_and_non_nominal_calibration(tmp_path: Path) -> None:
    from models.monitoring.fit import FitPlan, fit_monitor

    x = quantise(np.zeros((40, 64, 64, 3), np.float32))
    t = np.arange(40, dtype=np.float32) / 15
    (tmp_path / "train").mkdir()
    (tmp_path / "cal").mkdir()
    save_run(tmp_path / "train" / "a.npz", FailureRun("a", x, t, ((2.0, "off_road"),),
                                                       {"group": "perturbed", "seed_range": "evaluation"}))
    save_run(tmp_path / "cal" / "b.npz", FailureRun("b", x, t, (), {"group": "perturbed", "seed_range": "train"}))
    model = REPO / "models" / "pretrained" / "generalist.onnx"
    plan = FitPlan(model, tmp_path / "out.onnx", (tmp_path / "train",), (tmp_path / "cal",), score="predictor")
    with pytest.raises(BadValue, match="evaluation world"):
        fit_monitor(plan, say=lambda _: None)
    keep = FitPlan(model, tmp_path / "out.onnx", (), (tmp_path / "cal",), score="keep")
    with pytest.raises(BadValue, match="nominal driving on training worlds only"):
        fit_monitor(keep, say=lambda _: None)


def test_calibration_leaves_out_the_seconds_around_a_take_over_of_the_models_own_driving() -> None:
    """Windows before a real failure of a nominal run foresee it: they are not the nominal driving a false-alarm
    rate is set on (nor the 4 s after the car is put back)."""
    from models.monitoring.fit import _uneventful

    t = np.arange(0, 60, 1 / 15)
    x = np.arange(len(t), dtype=np.float32)[:, None]
    parts = _uneventful(x, t, ((30.0, "off_road"),))
    assert len(parts) == 2
    assert t[int(parts[0][-1, 0])] <= 20.0 and t[int(parts[1][0, 0])] >= 34.0
    assert sum(len(p) for p in parts) == int(((t <= 20.0) | (t >= 34.0)).sum())
    assert len(_uneventful(x, t, ())) == 1 and len(_uneventful(x, t, ())[0]) == len(t)
