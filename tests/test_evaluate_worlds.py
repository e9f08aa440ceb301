"""The unseen-worlds experiment (beyond the paper): its aggregation, its place in the tables, its worlds."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from tools.commands import eval as eval_command
from tools.evaluate.compare import TABLE10_EXPERIMENTS, build_table
from tools.evaluate.experiments import PAPER_EXPERIMENTS, experiment
from tools.evaluate.report import format_cell, table9
from tools.evaluate.runner import DriverSpec, Task, run_task
from tools.evaluate.suite import SuiteConfig, max_runs
from tools.evaluate.worlds import eval_world_seeds, summarize_worlds, write_eval_worlds
from tools.sim.worldgen import WorldGenConfig

SHORT = WorldGenConfig(min_length_m=200, max_length_m=400, drive_check=False)


def record(seed: int, etas: list[float], interventions: int = 0, completed: bool = True) -> dict:
    laps = [{"eta": e, "completed": completed, "n_interventions": interventions,
             "interventions": [{}] * interventions} for e in etas]
    return {"experiment": "unseen_worlds", "value": seed, "seed": 0, "laps": laps}


def test_mean_std_and_the_worst_world_over_worlds():
    entry = summarize_worlds([record(1_000_002, [90.0], 1), record(1_000_000, [100.0]),
                              record(1_000_001, [70.0, 80.0], 3), record(1_000_003, [75.0], 2)])
    assert entry["measure"] == "worlds" and entry["n"] == 4
    assert entry["mean"] == pytest.approx((90 + 100 + 75 + 75) / 4)
    assert entry["std"] == pytest.approx(112.5 ** 0.5)  # population std over worlds
    assert entry["worst"] == {"seed": 1_000_001, "eta": 75.0}  # ties go to the lowest seed
    assert entry["autonomous"] == 1 and [w["seed"] for w in entry["worlds"]] == [1_000_000 + k for k in range(4)]
    assert [w["interventions"] for w in entry["worlds"]] == [0, 6, 1, 2]
    assert format_cell(entry) == ("η = 85.0 ± 10.6 % over 4 worlds (1 with no take-over; "
                                  "worst: world 1000001, 75.0 %)")
    single = summarize_worlds([record(1_000_000, [100.0])])
    assert single["std"] == 0.0 and single["worst"] == {"seed": 1_000_000, "eta": 100.0}


def test_it_is_beyond_the_paper_and_not_run_by_default():
    exp = experiment("unseen_worlds")
    assert not exp.paper and "beyond the paper" in exp.title
    assert "unseen_worlds" not in PAPER_EXPERIMENTS and len(PAPER_EXPERIMENTS) == 8
    assert SuiteConfig().experiments == PAPER_EXPERIMENTS
    parser = argparse.ArgumentParser()
    eval_command.add_arguments(parser)
    args = parser.parse_args(["--out", "x"])
    assert tuple(args.experiments) == PAPER_EXPERIMENTS and args.worlds == 10
    worlds = tuple((1_000_000 + k, f"w{k}.json") for k in range(10))
    assert max_runs(SuiteConfig(experiments=("unseen_worlds",), worlds=worlds)) == 10  # no no-variation runs


def test_its_table_rows_only_where_it_ran():
    paper = {"no_variation": {"measure": "eta", "values": {"None": {"mean": 100.0, "std": 0.0}}}}
    worlds = paper | {"unseen_worlds": summarize_worlds([record(1_000_000, [80.0], 1), record(1_000_001, [100.0])])}
    assert "Unseen generated worlds" not in table9({"simplistic": paper})
    text = table9({"simplistic": worlds, "rigorous": paper})
    row = next(line for line in text.splitlines() if line.startswith("| Unseen generated worlds (beyond the paper)"))
    assert row.split(" | ")[1].startswith("η = 90.0 ± 10.0 % over 2 worlds") and row.split(" | ")[2] == "–"
    assert row.split(" | ")[3] == "n/a"  # the rigorous eval did not run it
    column = {"label": "generalist", "training_time_s": None, "summary": worlds,
              "latency": {"round_trip_ms": {"p50": 1.0, "p99": 2.0, "max": 3.0}}}
    table10 = build_table([column])
    assert "| Unseen generated worlds (beyond the paper) | η = 90.0" in table10
    assert sum(line.startswith("| ") for line in table10.splitlines()) == 1 + 2 + len(TABLE10_EXPERIMENTS) + 1
    assert "Unseen generated worlds" not in build_table([column | {"summary": paper}])


def test_worlds_come_from_the_evaluation_range_and_are_recorded(tmp_path):
    assert eval_world_seeds(3) == [1_000_000, 1_000_001, 1_000_002]
    assert eval_world_seeds(2, 1_500_000) == [1_500_000, 1_500_001]
    for bad in ((2, 0), (2, 1_999_999), (0, None)):
        with pytest.raises(ValueError):
            eval_world_seeds(*bad)
    meta = write_eval_worlds(tmp_path, [1_000_000], SHORT, resume=False)
    assert meta["seed_range"] == "eval" and meta["config"]["max_length_m"] == 400
    assert len(meta["sha256"]["1000000"]) == 64
    assert json.loads((tmp_path / "worlds" / "world-1000000.json").read_text())["name"] == "world-1000000"
    assert write_eval_worlds(tmp_path, [1_000_000], SHORT, resume=True) == meta
    with pytest.raises(ValueError, match="--resume"):  # other worlds under the same journal are refused
        write_eval_worlds(tmp_path, [1_000_000], WorldGenConfig(min_length_m=250, max_length_m=500,
                                                                drive_check=False), resume=True)


def test_the_world_document_travels_with_the_task(tmp_path):
    """A worker without the track file (a Ray node elsewhere) writes it where the run expects it."""
    from drive_server.serving.models_dir import demo_model_path

    path = write_eval_worlds(tmp_path, [1_000_001], SHORT, resume=False)["files"][1_000_001]
    doc = json.loads(Path(path).read_text())
    elsewhere = tmp_path / "node" / "worlds" / "world-1000001.json"
    scenario = {"track": str(elsewhere), "seed": 0, "laps": 1, "speed_limit_kmh": 30.0, "spawn_noise": True}
    rec = run_task(DriverSpec(model=str(demo_model_path())), Task("unseen_worlds", "simplistic", 1_000_001, 0,
                                                                     scenario, track_doc=doc))
    assert json.loads(elsewhere.read_text()) == doc and rec["config"]["track"] == str(elsewhere)
    assert rec["value"] == 1_000_001 and rec["laps"]


@pytest.mark.parametrize("flags", [["--worlds", "3"], ["--world-seed", "1000005"], ["--world-config", "{}"]])
def test_world_flags_without_the_experiment_are_a_one_line_error_before_any_output(tmp_path, flags):
    import subprocess
    import sys

    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "tools.cli", "eval", "--experiments", "no_variation", *flags,
                           "--out", str(out)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "unseen_worlds" in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()
