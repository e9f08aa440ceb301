"""In-process Ray cases of ``test_evaluate_ray``, each run in its own interpreter.

``ray.init`` leaves gRPC threads in the process that called it, and a process pool forked afterwards can
hang (it did once in the full suite), so the pytest process never imports Ray: each case runs here, in a
fresh ``python -m tests.ray_cases CASE FOLDER``, and prints its facts as one JSON line for the test.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from pathlib import Path

from drive_server.serving.models_dir import demo_model_path
from tests.conftest import write_stadium
from tools.evaluate.runner import DriverSpec, Runner, Task, record_key, run_task
from tools.evaluate.suite import SuiteConfig, run_suite

TIMINGS = ("wall_time_s", "latency_ms_p50", "latency_ms_p99")  # the only fields that may differ per machine


def comparable(records: list[dict]) -> dict[str, dict]:
    """Records by task key, without their timings (and maps by file name): what 'identical results' means."""
    return {record_key(r): {k: Path(v).name if k == "map" else v for k, v in r.items() if k not in TIMINGS}
            for r in records}


def start_ray() -> None:
    import ray

    ray.init(num_cpus=2, include_dashboard=False, _node_ip_address="127.0.0.1", log_to_driver=False)


def killed_worker(folder: Path) -> dict:
    """The pool's reference first (before Ray starts), then the same suite on Ray with one worker SIGKILLed."""
    import signal

    from tools.evaluate.cluster import RayRunner

    track = write_stadium(folder, straight=40.0, radius=20.0)
    cfg = SuiteConfig(track=track, experiments=("no_variation", "position"), seeds=2)
    spec = DriverSpec(model=str(demo_model_path()))
    local = Runner(spec, 2, folder / "pool.jsonl")
    try:
        local_summary = run_suite(cfg, local, 2)
    finally:
        local.close()

    start_ray()
    marker = folder / "victim.pid"

    def killable(spec: DriverSpec, task: Task) -> dict:
        """The first attempt of one run publishes its pid and waits to be SIGKILLed from outside."""
        if task.experiment == "position" and task.seed == 1 and not marker.exists():
            marker.write_text(str(os.getpid()))
            time.sleep(120)
        return run_task(spec, task)

    runner = RayRunner(spec, 2, folder / "ray.jsonl", task_fn=killable)
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
    journaled = [json.loads(line) for line in (folder / "ray.jsonl").read_text().splitlines()]
    return {"retried": runner.retried, "same_summary": result.get("summary") == local_summary,
            "same_records": comparable(journaled) == comparable(local.records),
            "journaled": len(journaled), "pool_runs": len(local.records)}


def lost_run(folder: Path) -> dict:
    """A run that fails on every attempt: a RunLostError for the waiter, nothing journaled."""
    from tools.evaluate.cluster import RayRunner, RunLostError

    def broken(spec: DriverSpec, task: Task) -> dict:
        raise RuntimeError("simulator exploded")

    start_ray()
    runner = RayRunner(DriverSpec(model="unused.onnx"), 2, folder / "runs.jsonl", retries=2, task_fn=broken)
    try:
        future = runner.submit(Task("position", "simplistic", 0.5, 3, {"seed": 3}))
        try:
            future.result(timeout=60)
            error = None
        except RunLostError as exc:
            error = str(exc)
    finally:
        runner.close()
    return {"error": error, "attempts": [r["attempt"] for r in runner.retried], "records": len(runner.records),
            "journal_exists": (folder / "runs.jsonl").exists()}


def submit_after_cancel(folder: Path) -> dict:
    """A range search's next step submitted while Ctrl-C closes the runner: cancelled at once, never queued."""
    from concurrent.futures import TimeoutError as FutureTimeout

    from tools.evaluate.cluster import RayRunner, RunLostError

    def slow(spec: DriverSpec, task: Task) -> dict:
        time.sleep(30)
        return {}

    start_ray()
    runner = RayRunner(DriverSpec(model="unused.onnx"), 2, folder / "runs.jsonl", task_fn=slow)
    in_flight = runner.submit(Task("position", "simplistic", 0.5, 1, {"seed": 1}))
    runner.close(cancel=True)
    late = runner.submit(Task("position", "simplistic", 1.0, 1, {"seed": 1}))
    outcome = {}
    for name, future in (("in_flight", in_flight), ("late", late)):
        try:
            future.result(timeout=5)
            outcome[name] = "result"
        except RunLostError:
            outcome[name] = "cancelled"
        except FutureTimeout:
            outcome[name] = "still waiting"
    return outcome


CASES = {"killed_worker": killed_worker, "lost_run": lost_run, "submit_after_cancel": submit_after_cancel}

if __name__ == "__main__":
    facts = CASES[sys.argv[1]](Path(sys.argv[2]))
    print(json.dumps(facts))
    sys.stdout.flush()
    os._exit(0)  # Ray's atexit hooks are not this case's business
