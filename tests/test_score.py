"""``rbc score``: open-loop figures of a model on a recorded log, computed through drive_server's pipeline."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from drive_server.serving.model import SteeringModel
from drive_server.serving.models_dir import bundled_model_path, bundled_models
from drive_server.serving.pipeline import DrivePipeline
from models.data.labels import centred_average
from protocol.datalog import read_log
from protocol.jpeg import read_jpeg_file
from tests.conftest import UDACITY_SAMPLE
from tools.evaluate.offline import score_models


def test_scores_are_the_pipelines_predictions_against_the_log():
    model = bundled_model_path("simplistic")
    (score,) = score_models([model], UDACITY_SAMPLE)
    samples, _ = read_log(UDACITY_SAMPLE)
    pipeline = DrivePipeline(SteeringModel(model))
    pred = np.array([pipeline.steer(read_jpeg_file(s.center, reduce=pipeline.reduce)) for s in samples])
    truth = np.array([s.steering for s in samples])
    assert score.frames == len(samples) > 0
    assert score.mse == pytest.approx(np.mean((pred - truth) ** 2))
    assert score.zero_mse == pytest.approx(np.mean(truth ** 2))
    assert score.pearson_r == pytest.approx(np.corrcoef(pred, truth)[0, 1])
    assert score.beats_zero == (score.mse < score.zero_mse)


def test_rbc_score_prints_every_bundled_model_and_writes_json(tmp_path):
    out = tmp_path / "scores.json"
    proc = subprocess.run([sys.executable, "-m", "tools.cli", "score", "--data", str(UDACITY_SAMPLE),
                           "--json", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    names = [p.name for p in bundled_models()]
    assert all(name in proc.stdout for name in names)
    doc = json.loads(out.read_text())
    assert [s["model"].rsplit("/", 1)[-1] for s in doc["scores"]] == names and doc["code_version"]


def test_rbc_score_on_a_missing_log_is_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "tools.cli", "score", "--data", str(tmp_path / "nope")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_smoothed_scores_are_against_the_centred_average_of_the_log():
    assert np.allclose(centred_average(np.array([0.0, 0.0, 0.9, 0.0, 0.0]), 3), [0, 0.3, 0.3, 0.3, 0])
    assert np.allclose(centred_average(np.array([1.0, 0.0, 0.0, 0.0]), 3), [0.5, 1 / 3, 0, 0])  # short ends
    assert np.allclose(centred_average(np.array([0.3, 0.0, 0.6]), 9), [0.3, 0.3, 0.3])  # window longer than the log
    model = bundled_model_path("simplistic")
    (plain,) = score_models([model], UDACITY_SAMPLE)
    (score,) = score_models([model], UDACITY_SAMPLE, smooth_frames=5)
    samples, _ = read_log(UDACITY_SAMPLE)
    pipeline = DrivePipeline(SteeringModel(model))
    pred = np.array([pipeline.steer(read_jpeg_file(s.center, reduce=pipeline.reduce)) for s in samples])
    intent = centred_average(np.array([s.steering for s in samples]), 5)
    assert (score.mse, score.pearson_r) == (plain.mse, plain.pearson_r) and plain.pearson_r_smoothed is None
    assert score.pearson_r_smoothed == pytest.approx(np.corrcoef(pred, intent)[0, 1])
    assert score.mse_smoothed == pytest.approx(np.mean((pred - intent) ** 2))
    truth = np.array([s.steering for s in samples])
    assert score.intent_r == pytest.approx(np.corrcoef(intent, truth)[0, 1]) and plain.intent_r is None


def test_rbc_score_smooth_labels_adds_a_column_and_checks_its_value(tmp_path):
    model = str(bundled_model_path("simplistic"))
    proc = subprocess.run([sys.executable, "-m", "tools.cli", "score", "--data", str(UDACITY_SAMPLE), "--model",
                           model, "--smooth-labels", "9"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "9-frame average" in proc.stdout, proc.stderr[-2000:]
    copy = tmp_path / "run" / "simplistic.onnx"  # same file name, other folder: both rows say which is which
    copy.parent.mkdir()
    copy.write_bytes(bundled_model_path("simplistic").read_bytes())
    both = subprocess.run([sys.executable, "-m", "tools.cli", "score", "--data", str(UDACITY_SAMPLE), "--model",
                           model, "--model", str(copy)], capture_output=True, text=True, timeout=120)
    assert both.returncode == 0 and model in both.stdout and str(copy) in both.stdout
    bad = subprocess.run([sys.executable, "-m", "tools.cli", "score", "--data", str(UDACITY_SAMPLE),
                          "--smooth-labels", "-1"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "Traceback" not in bad.stderr


def test_rbc_score_scores_a_log_whose_side_frames_are_absent(tmp_path, capsys):
    """Was: every row was skipped for a missing left/right frame, so a centre-only copy could not be scored."""
    from tools.cli import main

    data = tmp_path / "centre-only"
    (data / "IMG").mkdir(parents=True)
    (data / "driving_log.csv").write_bytes((UDACITY_SAMPLE / "driving_log.csv").read_bytes())
    centres = sorted((UDACITY_SAMPLE / "IMG").glob("center_*.jpg"))
    for frame in centres[1:]:  # the first row's centre frame is missing too: that row alone is skipped
        (data / "IMG" / frame.name).write_bytes(frame.read_bytes())
    samples, report = read_log(data)
    assert len(samples) == len(centres) - 1 and [s.line for s in report.skipped] == [1]
    assert all(s.left is None and s.right is None and not s.has_sides for s in samples)
    assert main(["score", "--data", str(data), "--model", str(bundled_model_path("simplistic"))]) == 0
    row = capsys.readouterr().out.splitlines()[1].split()
    assert row[:2] == ["simplistic.onnx", str(len(centres) - 1)]
