"""Table 10 writer: training time from a run's history, latency and robustness side by side."""

from pathlib import Path

import pytest

from tools.evaluate.compare import TABLE10_EXPERIMENTS, build_table, training_time_s
from tools.evaluate.evalrecord import EvalRecord


def test_training_time_sums_the_epochs(tmp_path):
    (tmp_path / "history.csv").write_text("epoch,train_loss,val_loss,seconds\n1,0.1,0.1,60.5\n2,0.1,0.1,59.5\n")
    assert training_time_s(tmp_path) == 120.0
    assert training_time_s(None) is None
    assert training_time_s(tmp_path / "missing") is None


def test_table10_rows_and_columns():
    column = {"label": "PilotNet, ours", "training_time_s": 600.0,
              "latency": {"server_total_ms": {"p50": 1.5, "p99": 2.1, "max": 3.0},
                          "round_trip_ms": {"p50": 1.9, "p99": 2.7, "max": 3.5}},
              "summary": {"no_variation": {"measure": "eta", "values": {"None": {"mean": 100.0, "std": 0.0}}}}}
    text = build_table([column])
    lines = text.splitlines()
    assert lines[0].startswith("| Parameter | PilotNet, ours | NVIDIA's approach (paper) | Our approach (paper) |")
    assert "| Training time | 10.0 min | ~1.8 hr | ~1.4 hr |" in text
    assert "server 1.50 ms (p99 2.10, max 3.0); round trip 1.90 ms (p99 2.70)" in text
    assert "| No variation | η = 100.0 ± 0.0 % |" in text
    assert sum(line.startswith("| ") for line in lines) == 1 + 2 + len(TABLE10_EXPERIMENTS)
    assert "Scene obstacle variation" not in text  # the paper's Table 10 leaves it out


def test_training_budget_and_validation_mse_rows(tmp_path):
    import json

    from tools.evaluate.compare import training_summary

    (tmp_path / "config.json").write_text(json.dumps({
        "config": {"arch": "pilotnet", "approach": "nvidia", "batch_size": 256, "aug_loops": 8},
        "resolved": {"epochs": 2, "steps_per_epoch": 280}}))
    (tmp_path / "history.csv").write_text("epoch,train_loss,val_loss,seconds\n1,0.2,0.015,60\n2,0.1,0.0125,60\n")
    train = training_summary(tmp_path)
    assert train["val_mse"] == 0.0125 and train["epochs"] == 2
    assert training_summary(None) == {} and training_summary(tmp_path / "missing") == {}
    column = {"label": "PilotNet, NVIDIA", "training_time_s": 120.0, "training": train,
              "latency": {"round_trip_ms": {"p50": 1.0, "p99": 2.0, "max": 3.0}}, "summary": {}}
    text = build_table([column], with_paper=False)
    assert "| Training budget | 2 × 280 steps of 256 (0.14 M samples) |" in text
    assert "| Validation MSE | 0.0125 |" in text


def test_range_chart_reads_offsets_caps_and_empty_ranges(tmp_path):
    import pytest

    from tools.evaluate.range_chart import measured_range, plot_ranges

    entry = {"measure": "range", "origin": 1.0, "caps": [0.1, 2.5],
             "lower": {"limit": 0.8, "hit_cap": False}, "upper": {"limit": 2.5, "hit_cap": True}}
    lo, hi, lo_cap, hi_cap = measured_range(entry)
    assert (lo, hi, lo_cap, hi_cap) == (pytest.approx(-0.2), pytest.approx(1.5), False, True)
    assert measured_range(entry | {"empty": True}) is None
    assert measured_range(None) is None
    assert measured_range({"measure": "eta", "values": {}}) is None
    pytest.importorskip("matplotlib")
    chart = plot_ranges([{"label": "a", "summary": {"light_intensity": entry}},
                         {"label": "b", "summary": {"light_intensity": entry | {"empty": True}}}],
                        tmp_path / "t10.png")
    assert chart == tmp_path / "t10.png" and chart.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob("*.tmp*"))


def test_compare_finds_an_evaluated_model_from_another_folder_and_refuses_a_moved_or_changed_one(tmp_path,
                                                                                                 monkeypatch):
    from protocol.runrecords import file_sha256
    from tools.errors import CommandError
    from tools.evaluate.compare import evaluated_model

    model = tmp_path / "models" / "m.onnx"
    model.parent.mkdir()
    model.write_bytes(b"weights")
    results = EvalRecord.from_dict({"meta": {"model": "models/m.onnx", "model_resolved": str(model),
                                             "model_sha256": file_sha256(model)}}, tmp_path)
    monkeypatch.chdir(tmp_path)
    assert evaluated_model(results) == Path("models/m.onnx")  # as given, from the eval's folder
    monkeypatch.chdir(model.parent)
    assert evaluated_model(results) == model  # from elsewhere: the recorded absolute path
    model.write_bytes(b"other weights")
    with pytest.raises(CommandError, match="has changed"):
        evaluated_model(results)
    model.unlink()
    with pytest.raises(CommandError, match="not found"):
        evaluated_model(results)
    old = EvalRecord.from_dict({"meta": {"model": "gone.onnx", "model_sha256": "x"}})  # of an earlier version
    with pytest.raises(CommandError, match="gone.onnx is not found"):
        evaluated_model(old)
