"""``rbc eval --backend ray``: the same records as the process pool, and a killed worker's run is retried."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from drive_server.models_dir import default_model_path
from tests.conftest import write_stadium
from tools.evaluate.runner import DriverSpec, Runner, record_key, run_task
from tools.evaluate.suite import SuiteConfig, run_suite

ray = pytest.importorskip("ray", reason="Ray is not installed (pip extra: cluster)")

TIMINGS = ("wall_time_s", "latency_ms_p50", "latency_ms_p99")  # the only fields that may differ per machine


def comparable(records: list[dict]) -> dict[str, dict]:
    """Records by task key, without their timings (and maps by file name): what 'identical results' means."""
    return {record_key(r): {k: Path(v).name if k == "map" else v for k, v in r.items() if k not in TIMINGS}
            for r in records}


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def track(tmp_path_factory) -> str:
    return write_stadium(tmp_path_factory.mktemp("track"), straight=40.0, radius=20.0)


@pytest.fixture(scope="module")
def pool_reference(tmp_path_factory, track) -> tuple[SuiteConfig, dict, list[dict]]:
    """The suite on the process pool, run before Ray starts: forking a process that runs Ray can hang."""
    cfg = SuiteConfig(track=track, experiments=("no_variation", "position"), seeds=2)
    local = Runner(DriverSpec(model=str(default_model_path())), 2, tmp_path_factory.mktemp("pool") / "runs.jsonl")
    try:
        return cfg, run_suite(cfg, local, 2), local.records
    finally:
        local.close()


def test_a_killed_worker_is_retried_and_the_results_equal_the_process_pool(tmp_path, pool_reference, local_ray):
    from tools.evaluate.cluster import RayRunner

    spec = DriverSpec(model=str(default_model_path()))
    cfg, local_summary, local_records = pool_reference

    marker = tmp_path / "victim.pid"

    def killable(spec: DriverSpec, task) -> dict:
        """The first attempt of one run publishes its pid and waits to be SIGKILLed from outside."""
        if task.experiment == "position" and task.seed == 1 and not marker.exists():
            marker.write_text(str(os.getpid()))
            time.sleep(120)
        return run_task(spec, task)

    journal = tmp_path / "ray.jsonl"
    runner = RayRunner(spec, 2, journal, task_fn=killable)
    result: dict = {}
    suite = threading.Thread(target=lambda: result.update(summary=run_suite(cfg, runner, runner.workers)))
    try:
        suite.start()
        deadline = time.monotonic() + 60
        while not marker.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(int(marker.read_text()), signal.SIGKILL)  # the worker dies mid-run
        suite.join(timeout=120)
    finally:
        runner.close()
    ray_summary = result["summary"]
    assert [(r["experiment"], r["seed"], r["attempt"]) for r in runner.retried] == [("position", 1, 1)]
    assert "WorkerCrashed" in runner.retried[0]["error"] or "died" in runner.retried[0]["error"].lower()
    assert ray_summary == local_summary
    journaled = [json.loads(line) for line in journal.read_text().splitlines()]
    assert comparable(journaled) == comparable(local_records)  # every run journaled, none missing, none twice
    assert len(journaled) == len(local_records)


def test_a_run_that_fails_every_attempt_is_reported_not_dropped(tmp_path, local_ray):
    from tools.evaluate.cluster import RayRunner, RunLostError
    from tools.evaluate.runner import Task

    def broken(spec, task):
        raise RuntimeError("simulator exploded")

    runner = RayRunner(DriverSpec(model="unused.onnx"), 2, tmp_path / "runs.jsonl", retries=2, task_fn=broken)
    try:
        future = runner.submit(Task("position", "simplistic", 0.5, 3, {"seed": 3}))
        with pytest.raises(RunLostError, match="failed 3 times.*simulator exploded.*--resume"):
            future.result(timeout=60)
    finally:
        runner.close()
    assert [r["attempt"] for r in runner.retried] == [1, 2]
    assert runner.records == [] and not (tmp_path / "runs.jsonl").exists()


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
