"""``rbc eval --backend ray``: the same records as the process pool, and a killed worker's run is retried."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import write_stadium
from tests.ray_cases import TIMINGS, comparable

if importlib.util.find_spec("ray") is None:  # found, not imported: the pytest process never starts Ray
    pytest.skip("Ray is not installed (pip extra: cluster)", allow_module_level=True)

ROOT = Path(__file__).resolve().parents[1]


def ray_case(name: str, folder: Path) -> dict:
    """One case of ``tests/ray_cases.py`` in its own interpreter (see its docstring for why)."""
    proc = subprocess.run([sys.executable, "-m", "tests.ray_cases", name, str(folder)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_killed_worker_is_retried_and_the_results_equal_the_process_pool(tmp_path):
    facts = ray_case("killed_worker", tmp_path)
    assert [(r["experiment"], r["seed"], r["attempt"]) for r in facts["retried"]] == [("position", 1, 1)]
    error = facts["retried"][0]["error"]
    assert "WorkerCrashed" in error or "died" in error.lower()
    assert facts["same_summary"]
    assert facts["same_records"]  # every run journaled, none missing
    assert facts["journaled"] == facts["pool_runs"]  # none twice


def test_a_run_that_fails_every_attempt_is_reported_not_dropped(tmp_path):
    facts = ray_case("lost_run", tmp_path)
    assert re.search("failed 3 times.*simulator exploded.*--resume", facts["error"] or "")
    assert facts["attempts"] == [1, 2]
    assert facts["records"] == 0 and not facts["journal_exists"]


def test_a_run_submitted_after_ctrl_c_is_cancelled_not_left_waiting(tmp_path):
    """The race behind a hang at exit: a range search's next step landed after close(cancel=True)."""
    assert ray_case("submit_after_cancel", tmp_path) == {"in_flight": "cancelled", "late": "cancelled"}


@pytest.fixture(scope="module")
def track(tmp_path_factory) -> str:
    return write_stadium(tmp_path_factory.mktemp("track"), straight=40.0, radius=20.0)


def _eval(out: Path, track: str, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "tools.cli", "eval", "--track", track, "--experiments", "no_variation", "position",
         "--seeds", "2", "--workers", "2", "--out", str(out), *extra],
        capture_output=True, text=True, timeout=240)


def test_rbc_eval_backend_ray_equals_local_and_resumes(tmp_path, track):
    local = _eval(tmp_path / "local", track)
    assert local.returncode == 0, local.stderr[-3000:]
    first = _eval(tmp_path / "ray", track, "--backend", "ray")
    assert first.returncode == 0, first.stderr[-3000:]
    a, b = (json.loads((tmp_path / d / "results.json").read_text()) for d in ("local", "ray"))
    assert b["meta"]["backend"] == "ray" and b["meta"]["retried"] == []
    assert b["summary"] == a["summary"] and comparable(b["runs"]) == comparable(a["runs"])
    assert (tmp_path / "ray" / "table9.md").read_text() == (tmp_path / "local" / "table9.md").read_text()

    journal = tmp_path / "ray" / "runs.jsonl"
    lines = journal.read_text().splitlines()
    journal.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2])  # cut mid-write
    resumed = _eval(tmp_path / "ray", track, "--backend", "ray", "--resume")
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    c = json.loads((tmp_path / "ray" / "results.json").read_text())
    assert c["meta"]["resumed_runs"] == len(lines) - 1 and c["summary"] == a["summary"]


def test_address_without_the_ray_backend_is_a_one_line_error(tmp_path, track):
    proc = _eval(tmp_path / "x", track, "--address", "auto")
    assert proc.returncode == 2 and "--address" in proc.stderr and "Traceback" not in proc.stderr


def test_ctrl_c_under_ray_keeps_the_finished_runs_and_resume_completes(tmp_path):
    """The bundled model drives this stadium, so the orientation search takes ~16 runs: time to press Ctrl-C."""
    track = write_stadium(tmp_path, straight=60.0, radius=30.0, road_width=10.0)
    out = tmp_path / "cut"
    cmd = [sys.executable, "-m", "tools.cli", "eval", "--track", track, "--experiments", "no_variation", "orientation",
           "--seeds", "1", "--workers", "2", "--backend", "ray", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    journal, deadline = out / "runs.jsonl", time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if journal.is_file() and journal.read_text().count("\n") >= 2:
            break
        time.sleep(0.02)
    if proc.poll() is not None:
        pytest.skip("the evaluation finished before it could be interrupted")
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-3000:]
    journaled = [json.loads(line) for line in journal.read_text().splitlines()]
    assert journaled and not any(r.get("interrupted") for r in journaled)
    resumed = subprocess.run(cmd + ["--resume"], capture_output=True, text=True, timeout=240)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert json.loads((out / "results.json").read_text())["meta"]["resumed_runs"] == len(journaled)



def test_unseen_worlds_under_ray_equal_the_process_pool(tmp_path):
    """The world documents travel with the tasks; the records are the process pool's (but for the track path)."""
    def unseen(out: Path, *extra: str) -> dict:
        proc = subprocess.run(
            [sys.executable, "-m", "tools.cli", "eval", "--experiments", "unseen_worlds", "--worlds", "2",
             "--world-seed", "1000010", "--world-config", '{"min_length_m": 200, "max_length_m": 400, '
             '"drive_check": false}', "--workers", "2", "--out", str(out), *extra],
            capture_output=True, text=True, timeout=240)
        assert proc.returncode == 0, proc.stderr[-3000:]
        results = json.loads((out / "results.json").read_text())
        skip = {"map", "config", "scenario", *TIMINGS}  # config and scenario name the track file, under --out
        return {"meta": results["meta"]["worlds"]["sha256"], "summary": results["summary"]["unseen_worlds"]["n"],
                "runs": {r["value"]: {k: v for k, v in r.items() if k not in skip} for r in results["runs"]}}

    local, ray = unseen(tmp_path / "local"), unseen(tmp_path / "ray", "--backend", "ray")
    assert ray == local and ray["summary"] == 2
