"""``rbc eval`` interrupted with Ctrl-C (SIGINT to the whole process group, as a terminal sends it) journals
only finished runs, and the resumed table equals an uninterrupted one (issue #10 item 11)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from drive_server.serving.models_dir import demo_model_path
from tests.conftest import write_stadium
from tools.evaluate.runner import read_journal

pytestmark = pytest.mark.slow


def _cmd(model, track, out, *extra):
    return [sys.executable, "-m", "tools.cli", "eval", "--model", str(model), "--track", track,
            "--experiments", "no_variation", "orientation", "--seeds", "1", "--workers", "2", "--out", str(out),
            *extra]


def _table(out):
    return (out / "table9.md").read_text(encoding="utf-8")


def _interrupt(cmd, journal) -> tuple[list[dict], str]:
    """Start ``cmd``, press Ctrl-C a moment after its third run is journaled; (journaled runs, stderr)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if journal.is_file() and journal.read_text().count("\n") >= 3:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the evaluation finished before it could be interrupted"
    time.sleep(0.3)  # the range searches have submitted their next runs: both workers are driving
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the CLI and its worker processes all get SIGINT
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-3000:]
    return [json.loads(line) for line in journal.read_text().splitlines() if line.strip()], err


def test_interrupted_eval_resumes_to_the_uninterrupted_table(tmp_path):
    """The bundled model drives this stadium, so the orientation range search runs ~16 runs of ~1 s."""
    model = demo_model_path()
    track = write_stadium(tmp_path, straight=60.0, radius=30.0, road_width=10.0)
    reference = subprocess.run(_cmd(model, track, tmp_path / "ref"), capture_output=True, text=True,
                               timeout=300)
    assert reference.returncode == 0, reference.stderr[-3000:]
    total = len(json.loads((tmp_path / "ref" / "results.json").read_text())["runs"])

    for attempt in range(3):  # until Ctrl-C lands while a run is in progress (it nearly always does)
        out = tmp_path / f"cut{attempt}"
        journaled, err = _interrupt(_cmd(model, track, out), out / "runs.jsonl")
        if "interrupted at t=" in err:  # a worker's simulator was cut short mid-run
            break
    else:
        pytest.skip("SIGINT never arrived while a run was in progress")
    assert 3 <= len(journaled) < total
    assert not any(r.get("interrupted") for r in journaled), "a run cut short was journaled"

    resumed = subprocess.run(_cmd(model, track, out, "--resume"), capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert _table(out) == _table(tmp_path / "ref")
    meta = json.loads((out / "results.json").read_text())["meta"]
    assert meta["resumed_runs"] == len(journaled)


def test_a_journal_with_interrupted_runs_from_an_older_version_reruns_them(tmp_path):
    journal = tmp_path / "runs.jsonl"
    done = {"experiment": "orientation", "value": 5.0, "seed": 0, "scenario": {"track": "t", "seed": 0}}
    journal.write_text(json.dumps(done) + "\n" + json.dumps(done | {"value": 10.0, "interrupted": True}) + "\n")
    assert [r["value"] for r in read_journal(journal).values()] == [5.0]
