"""The offline study of candidate monitor scores (tools.monitoreval.study) on a synthetic two-run set."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from models.monitoring.failures import FailureRun, save_run
from tools.monitoreval.candidates import window_std
from tools.monitoreval.modelfiles import degraded_model, file_digest
from tools.monitoreval.study import DEFAULT_MODEL, ScoredRun, evaluate, main, roc_auc, uneventful

RATE = 15.0


def test_roc_auc_ranks_with_ties() -> None:
    assert roc_auc(np.array([2.0, 3.0]), np.array([0.0, 1.0])) == 1.0
    assert roc_auc(np.array([0.0]), np.array([1.0, 2.0])) == 0.0
    assert roc_auc(np.zeros(3), np.zeros(5)) == 0.5
    assert roc_auc(np.array([1.0, 2.0]), np.array([1.0, 0.0])) == 0.875  # the tie counts half
    assert roc_auc(np.zeros(0), np.ones(2)) is None


def test_window_std_is_the_std_of_the_last_frames() -> None:
    x = np.array([0.0, 2.0, 0.0, 2.0, 5.0, 5.0])
    expected = [0.0, 1.0, np.std([0, 2, 0]), np.std([2, 0, 2]), np.std([0, 2, 5]), np.std([2, 5, 5])]
    assert np.allclose(window_std(x, 3), expected)


def test_calibration_stretches_leave_out_the_take_overs() -> None:
    t = np.arange(0, 30, 1 / RATE)
    spans = uneventful(t, [(15.0, "off_road")])
    assert [(round(t[a], 2), round(t[b - 1], 2)) for a, b in spans] == [(0.0, 5.0), (19.0, 29.93)]


def _scored(name: str, axis: str, rising: bool) -> ScoredRun:
    """A 30 s run with a misbehaviour at 20 s; its score rises over the 4 s before it, or stays flat."""
    t = np.arange(0, 30, 1 / RATE)
    s = np.where((t > 16) & (t < 20), 1.0, 0.0) if rising else np.zeros_like(t)
    return ScoredRun(name, axis, "perturbed", t, [(20.0, "off_road")], 30.0, {"score": s})


def test_a_score_that_rises_before_the_failure_is_found_and_a_flat_one_is_not() -> None:
    calibration = {"score": np.zeros(1000)}
    rising = evaluate([_scored("r", "yaw", True)], calibration, ["score"])["score"]
    assert rising["threshold"] == 0.0 and rising["threshold_is_zero"]
    assert rising["axes"]["yaw"]["auc"] == 1.0
    assert rising["axes"]["yaw"]["recall_at"] == {"1": 1.0, "2": 1.0, "3": 1.0}
    assert rising["axes"]["all"]["misbehaviours"] == 1 and rising["axes"]["yaw"]["alarmed_negatives"] == 0.0
    flat = evaluate([_scored("f", "light", False)], calibration, ["score"])["score"]
    assert flat["axes"]["light"]["auc"] == 0.5
    assert flat["axes"]["light"]["recall_at"] == {"1": 0.0, "2": 0.0, "3": 0.0}
    assert "yaw" not in flat["axes"]


def _run(folder: Path, name: str, frames: int, meta: dict, takeovers: tuple = ()) -> None:
    rng = np.random.default_rng(len(name))
    base = rng.integers(0, 256, (1, 64, 64, 3))
    drift = rng.integers(-20, 21, (frames, 1, 1, 3))
    inputs = np.clip(base + drift, 0, 255).astype(np.uint8)
    t = (np.arange(frames) / RATE).astype(np.float32)
    save_run(folder / f"{name}.npz", FailureRun(name, inputs, t, takeovers, {"sim_time_s": frames / RATE, **meta}))


def _synthetic(tmp_path: Path, digest: str) -> tuple[Path, Path]:
    failures, calibration = tmp_path / "failures", tmp_path / "calibration"
    failures.mkdir()
    calibration.mkdir()
    nominal = {"group": "nominal", "axis": "none", "weight_noise": 0.0, "seed": 700, "model_sha256": digest}
    _run(failures, "train-nominal-0", 300, nominal, ((12.0, "off_road"),))
    _run(failures, "train-noise0.3-0", 300, {**nominal, "group": "degraded", "axis": "weight_noise",
                                              "weight_noise": 0.3, "seed": 500}, ((14.0, "off_road"),))
    _run(calibration, "calibration-0", 150, {**nominal, "seed": 800})
    return failures, calibration


def test_the_study_on_a_synthetic_two_run_set(tmp_path: Path) -> None:
    failures, calibration = _synthetic(tmp_path, file_digest(DEFAULT_MODEL))
    cached = degraded_model(DEFAULT_MODEL, failures / "models", 0.3, 500)  # the copy that drove, as the runs keep it
    others = tmp_path / "others"
    others.mkdir()
    shutil.copy(DEFAULT_MODEL, others / "twin.onnx")  # the same contract: compared
    shutil.copy(DEFAULT_MODEL.parent / "simplistic.onnx", others / "simplistic.onnx")  # another crop: not compared
    out = tmp_path / "study.json"
    assert main(["--failures", str(failures), "--calibration", str(calibration), "--json", str(out),
                 "--others", str(others), "--members", "1"]) == 0
    result = json.loads(out.read_text())
    assert result["data"]["failure_runs"] == 2 and result["data"]["calibration_frames"] == 150
    assert result["same_contract"] == {"simplistic.onnx": "64x64, crop 0..160, decode 1/1", "twin.onnx": "same"}
    assert result["noise_copies"] == [{"run": "train-noise0.3-0", "sigma": 0.3, "seed": 500,
                                       "sha256": file_digest(cached), "matches_cached_copy": True}]
    scores = result["scores"]
    assert {"carried", "shift", "steer_std", "vs_reference", "vs_twin", "ensemble", "mirror",
            "perturbed"} <= set(scores)
    # a calibration lap is served by the reference itself: its distance to the reference is 0 on every frame, as
    # is a nominal run's; the recreated noisy copy steers otherwise, so every window of its run is above 0
    ref = scores["vs_reference"]
    assert ref["threshold_is_zero"] and ref["axes"]["none"]["auc"] == 0.5
    assert ref["axes"]["none"]["alarmed_negatives"] == 0.0 and ref["axes"]["weight_noise"]["alarmed_negatives"] == 1.0
    assert scores["ensemble"]["threshold_is_zero"] and scores["ensemble"]["axes"]["none"]["auc"] == 0.5
    assert not scores["steer_abs"]["threshold_is_zero"]
    assert scores["steer_abs"]["axes"]["all"]["misbehaviours"] == 2


def test_runs_of_another_model_file_are_refused_in_one_line(tmp_path: Path, capsys) -> None:
    failures, calibration = _synthetic(tmp_path, "0123456789abcdef")
    assert main(["--failures", str(failures), "--calibration", str(calibration), "--json", str(tmp_path / "o.json"),
                 "--others", str(tmp_path), "--members", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("study: error: train-noise0.3-0 was driven by a copy of a model file 0123456789abcdef")
    assert not (tmp_path / "o.json").exists()


def test_the_ensemble_monitors_own_score_is_a_candidate_with_two_members_or_more() -> None:
    from tools.monitoreval.candidates import Served, candidates, window_scores

    n = 30
    served = Served(np.full(n, 0.3), None, np.zeros(n), [])
    one = {"a": np.full(n, 0.1)}
    two = {"a": np.full(n, 0.1), "b": np.full(n, 0.3)}
    frame = {"carried": np.zeros(n), "reference": served, "served": served}
    assert "ensemble_monitor" not in window_scores({**frame, "others": one})
    assert "ensemble_monitor" not in {c.key for c in candidates(["a"], False, 0, 0.1)}
    # |0.3 - mean(0.1, 0.3)| + std(0.1, 0.3) = 0.1 + 0.1, as rbc monitor fit --score ensemble scores a frame
    assert np.allclose(window_scores({**frame, "others": two})["ensemble_monitor"], 0.2)
    assert {"ensemble_monitor", "ensemble_spread"} <= {c.key for c in candidates(["a", "b"], False, 0, 0.1)}
    steering = np.where(np.arange(n) % 2 == 0, 0.2, 0.4)  # the served steering swings by 0.1 around 0.3
    swinging = window_scores({**frame, "served": Served(steering, None, np.zeros(n), []), "others": two})
    assert np.allclose(swinging["ensemble_spread"][15:], swinging["ensemble_monitor"][15:] + 0.1, atol=1e-3)
