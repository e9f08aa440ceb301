"""A small robustness evaluation end to end: worker processes driving the real drive server."""

import json
import subprocess
import sys

from tests.conftest import write_stadium
from tools.evaluate.evalrecord import EvalRecord
from tools.wire.server_process import ServerProcess


def test_eval_over_the_socket_writes_results_and_table(tmp_path, shallow_onnx):
    track = write_stadium(tmp_path, straight=60.0, radius=30.0)
    out = tmp_path / "eval"
    with ServerProcess(shallow_onnx, ["--log-every", "0"]) as server:
        proc = subprocess.run(
            [sys.executable, "-m", "tools.cli", "eval", "--model", str(shallow_onnx), "--server", server.url,
             "--track", track, "--experiments", "no_variation", "orientation", "speed_limit", "--seeds", "2",
             "--workers", "2", "--out", str(out)],
            capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    meta = results["meta"]
    assert len(meta["model_sha256"]) == 64 and meta["code_version"] and meta["seeds"] == 2
    assert meta["autonomy_rule"].startswith("no take-over")
    runs = results["runs"]
    assert sorted(r["seed"] for r in runs if r["experiment"] == "no_variation") == [0, 1]
    for r in runs:  # every run carries its parameters, seed, eta, interventions and timings
        assert {"config", "laps", "wall_time_s", "autonomous", "value"} <= set(r)
        assert r["config"]["track"] == track
    summary = results["summary"]
    assert summary["no_variation"]["values"]["None"]["n"] == 2
    # speed limit is skipped over --server (the limit belongs to the server), and said so
    assert "speed_limit" not in summary
    # a random-weight model leaves the road, so the range around no-variation is empty
    if not any(r["autonomous"] for r in runs if r["experiment"] == "no_variation" and r["seed"] == 0):
        assert summary["orientation"].get("empty")
    table = (out / "table9.md").read_text()
    assert "| No variation |" in table and "Vehicle orientation variation" in table
    assert "Robustness of shallow.onnx" in proc.stdout
    record = EvalRecord.load(out)  # what rbc compare reads: the same record, typed
    assert (record.meta, record.summary, list(record.runs)) == (meta, summary, runs)
    assert (record.model, record.model_sha256) == (shallow_onnx, meta["model_sha256"])
    assert record.behavior == meta["behavior"]


WORLDS_CONFIG = '{"min_length_m": 200, "max_length_m": 400, "drive_check": false}'  # 0.2-0.4 km loops


def test_unseen_worlds_over_the_socket_two_tiny_worlds(tmp_path):
    """The experiment beyond the paper: two generated evaluation worlds, the bundled model on the real server."""
    from drive_server.serving.models_dir import demo_model_path

    out = tmp_path / "eval"
    with ServerProcess(demo_model_path(), ["--log-every", "0"]) as server:
        proc = subprocess.run(
            [sys.executable, "-m", "tools.cli", "eval", "--server", server.url, "--experiments", "unseen_worlds",
             "--worlds", "2", "--world-config", WORLDS_CONFIG, "--workers", "2", "--out", str(out)],
            capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    worlds = results["meta"]["worlds"]
    assert worlds["seeds"] == [1_000_000, 1_000_001] and worlds["seed_range"] == "eval"
    assert worlds["config"]["max_length_m"] == 400 and worlds["generator_version"] >= 1
    assert sorted(p.name for p in (out / "worlds").iterdir()) == ["world-1000000.json", "world-1000001.json"]
    runs = results["runs"]
    assert sorted(r["value"] for r in runs) == worlds["seeds"] and {r["seed"] for r in runs} == {0}
    assert {r["config"]["track"] for r in runs} == set(worlds["files"].values())
    entry = results["summary"]["unseen_worlds"]
    assert entry["n"] == 2 and entry["worst"]["eta"] == min(w["eta"] for w in entry["worlds"])
    for w in entry["worlds"]:  # every failed run has its trajectory map
        assert w["autonomous"] or (w["map"] and (out / "failures" / f"unseen_worlds_{w['seed']}_seed0.png").is_file())
    assert list(results["summary"]) == ["unseen_worlds"]  # nothing else ran
    row = next(line for line in (out / "table9.md").read_text().splitlines() if "Unseen generated worlds" in line)
    assert "over 2 worlds" in row and (out / "unseen_worlds.png").is_file()
    assert "Unseen generated worlds (beyond the paper)" in proc.stdout
    table = tmp_path / "table9.md"
    compare = subprocess.run([sys.executable, "-m", "tools.cli", "compare", "--layout", "table9", "--eval", str(out),
                              "--out", str(table)], capture_output=True, text=True, timeout=60)
    assert compare.returncode == 0, compare.stderr[-2000:]
    assert "| Unseen generated worlds (beyond the paper) | η = " in table.read_text()
