"""A small robustness evaluation end to end: worker processes driving the real drive server."""

import json
import subprocess
import sys

from tests.conftest import write_stadium
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
    assert meta["autonomy_rule"].startswith("no intervention")
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
