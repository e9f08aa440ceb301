"""Commands parse, libraries run a typed plan: rbc sim-bench, train-bench, bench and data crossval build a frozen plan
from their flags (whose defaults are the plan's) and hand it to one library function (issue 51, item 6)."""

from __future__ import annotations

import json
from dataclasses import FrozenInstanceError, replace
from pathlib import Path
from typing import Any

import pytest

from tools.bench.latency import LatencyPlan
from tools.bench.simulator import SimBenchPlan
from tools.bench.training import TrainBenchPlan
from tools.cli import main
from tools.drivelog.loop import LoopRules
from tools.errors import CommandError
from tools.realdata.crossval_run import CrossvalPlan, run_crossval

DATA = Path(__file__).parent / "data"
MODEL = Path(__file__).parents[1] / "models" / "pretrained" / "unity.onnx"


def _planned(monkeypatch: pytest.MonkeyPatch, module: str, function: str, argv: list[str]) -> Any:
    """The plan the command ``argv`` hands to ``module.function`` (not run)."""
    import importlib

    plans: list[Any] = []
    monkeypatch.setattr(importlib.import_module(module), function, lambda plan: plans.append(plan) or 0)
    assert main(argv) == 0
    (plan,) = plans
    return plan


def test_each_commands_defaults_are_its_plans(monkeypatch: pytest.MonkeyPatch) -> None:
    """Was: the defaults lived in the flags and the libraries read the flags' Namespace; now the plan's fields are
    the flags' defaults, so the command with no flags hands over the default plan."""
    assert _planned(monkeypatch, "tools.commands.sim_bench", "run_sim_bench", ["sim-bench"]) == SimBenchPlan()
    assert _planned(monkeypatch, "tools.commands.train_bench", "benchmark", ["train-bench"]) == TrainBenchPlan()
    latency = _planned(monkeypatch, "tools.commands.bench", "run_bench", ["bench"])
    assert replace(latency, monitor=None) == LatencyPlan() and latency.monitor in ("off", "warn", "act")
    crossval = _planned(monkeypatch, "tools.commands.data", "run_crossval", ["data", "crossval", "--models", "m.onnx"])
    assert crossval == CrossvalPlan(models="m.onnx")
    with pytest.raises(FrozenInstanceError):
        crossval.workers = 3  # type: ignore[misc]


def test_each_flag_reaches_its_plan(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    sim = _planned(monkeypatch, "tools.commands.sim_bench", "run_sim_bench",
                   ["sim-bench", "--tracks", "lake", "--frames", "5", "--repeats", "1", "--no-sheet", "--no-lap",
                    "--vehicles", "kinematic", "--cones", "0"])
    assert sim == replace(SimBenchPlan(), tracks=("lake",), frames=5, repeats=1, sheet=None, lap=False,
                          vehicles=("kinematic",), cones=0)
    latency = _planned(monkeypatch, "tools.commands.bench", "run_bench",
                       ["bench", "--log", str(tmp_path), "--json", str(tmp_path / "b.json"), "--monitor", "off",
                        "--stock-transport", "--clients", "2"])
    assert (latency.log_dir, latency.json_out, latency.monitor, latency.stock_transport, latency.clients) == (
        tmp_path, tmp_path / "b.json", "off", True, 2)
    train = _planned(monkeypatch, "tools.commands.train_bench", "benchmark",
                     ["train-bench", "--data", "a", "--data", "b", "--steps", "2", "--threads", "1"])
    assert (train.data, train.steps, train.threads) == (("a", "b"), 2, 1)
    crossval = _planned(monkeypatch, "tools.commands.data", "run_crossval",
                        ["data", "crossval", "--models", "m-{fold}.onnx", "--name", "a", "--name", "b",
                         "--no-closed-loop", "--handback", "0", "--smooth", "0.5", "--lane", "path"])
    assert crossval == CrossvalPlan(models="m-{fold}.onnx", names=("a", "b"), closed_loop=False, smooth=0.5,
                                    rules=LoopRules(lane="path", handback_s=0.0))


def test_a_crossval_runs_from_a_plan_without_a_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Was: rbc data crossval's orchestration (checks, folds, journal, JSON after each fold, tables, plot) was the
    command's body, reachable only through a command line."""
    root = tmp_path / "real"
    root.mkdir()
    (root / "0xR4Y").symlink_to(DATA / "udacity-sample")  # fold A of the manifest
    out = tmp_path / "cv.json"
    plan = CrossvalPlan(root=root, models=str(MODEL), names=("0xR4Y",), closed_loop=False, workers=1, json_out=out)
    assert run_crossval(plan) == 0
    record = json.loads(out.read_text(encoding="utf-8"))
    assert (record["folds_done"], record["closed_loop"], record["lane"], record["models"]) == (
        ["A"], False, "road", str(MODEL))
    (scored,) = record["folds"]["recordings"]
    assert scored["name"] == "0xR4Y" and scored["frames"] == 36 and scored["eta"] is None
    assert "| 0xR4Y |" in capsys.readouterr().out
    with pytest.raises(CommandError, match="--workers must be 1..64"):
        run_crossval(replace(plan, workers=0))
    with pytest.raises(CommandError, match="no model at"):
        run_crossval(replace(plan, models=str(tmp_path / "cv-{fold}.onnx")))
