"""Run scenarios in parallel worker processes, one simulator (and one driver) per worker.

Each run is independent, so a process pool scales them over the cores. Over the socket, several
workers share one drive server (each opens its own Unity-wire connection); in-process, each worker
holds its own ONNX Runtime session.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drive_server.serving.control import ControlLaw
from protocol.appending import append_record
from tools.evaluate.evalrecord import EvalRun, Retry

if TYPE_CHECKING:
    from tools.evaluate.experiments import AxisValue
    from tools.sim.driving.drivers import OnnxDriver, SocketDriver

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DriverSpec:
    """How workers drive: an in-process ONNX model, or a running drive server over the socket."""

    model: str | None = None
    server: str | None = None
    threads: int = 1
    law: ControlLaw = ControlLaw()  # Eq. 14 of an in-process model; its speed limit is each scenario's
    monitor: str = "off"  # the in-process model's misbehaviour monitor: off, warn or act (drive_server --monitor)

    def __post_init__(self) -> None:
        if self.model is None and self.server is None:
            raise ValueError("give a model (in-process) or a server URL")


@dataclass(frozen=True)
class Task:
    """One run: which experiment it belongs to, the varied value, the seed and the scenario."""

    experiment: str
    behavior: str
    value: AxisValue
    seed: int
    scenario: dict[str, Any] = field(default_factory=dict)  # ScenarioConfig keyword arguments
    map_dir: str | None = None  # write a trajectory map here if the run is not autonomous
    # a generated world's track document: written to scenario["track"] by a worker that lacks the file
    # (a Ray node of another machine), so the run and its record are the driver's
    track_doc: Mapping[str, object] | None = field(default=None, compare=False, repr=False)


_DRIVERS: dict[tuple[DriverSpec, float | None], OnnxDriver | SocketDriver] = {}


def _driver(spec: DriverSpec, speed_limit_kmh: float):
    """One driver per worker process (and per speed limit for the in-process control law)."""
    from tools.sim.driving.drivers import OnnxDriver, SocketDriver

    key = (spec, speed_limit_kmh if spec.model and not spec.server else None)
    if key not in _DRIVERS:
        if spec.server:
            _DRIVERS[key] = SocketDriver(spec.server)
        elif spec.model:
            from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy

            law = replace(spec.law, speed_limit_kmh=speed_limit_kmh)  # the scenario's speed limit
            _DRIVERS[key] = OnnxDriver(spec.model, law=law, threads=spec.threads,
                                       monitor=MonitorPolicy(mode=MonitorMode(spec.monitor)))
        else:
            raise ValueError("give a model (in-process) or a server URL")
    return _DRIVERS[key]


def run_task(spec: DriverSpec, task: Task) -> EvalRun:
    """Execute one task (in a worker process) and return a JSON-ready record."""
    import cv2

    cv2.setNumThreads(1)
    from tools.evaluate.experiments import is_autonomous
    from tools.sim.driving.drivers import OnnxDriver
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.session import run_scenario
    from tools.sim.track.files import write_track_file

    if task.track_doc is not None and not Path(task.scenario["track"]).is_file():
        write_track_file(task.scenario["track"], task.track_doc)  # a worker on a node without the file
    config = ScenarioConfig(**task.scenario)
    started = time.perf_counter()
    driver = _driver(spec, config.speed_limit_kmh)
    result = run_scenario(config, driver)
    record: EvalRun = {"experiment": task.experiment, "behavior": task.behavior, "value": task.value, "seed": task.seed,
              "wall_time_s": round(time.perf_counter() - started, 3), **result.to_dict(), "scenario": task.scenario}
    record["autonomous"] = is_autonomous(record)
    if isinstance(driver, OnnxDriver) and driver.monitor is not None:  # --monitor warn|act, a model carrying one
        from tools.evaluate.monitor import run_monitor

        record["monitor"] = run_monitor(driver, result)
    if task.map_dir and not record["autonomous"]:
        from tools.sim.pictures.viz import write_trajectory_map

        path = Path(task.map_dir) / f"{task.experiment}_{task.value}_seed{task.seed}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        write_trajectory_map(result, path)
        record["map"] = str(path)
    return record


def _init_worker() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def task_key(experiment: str, value: AxisValue, seed: int, scenario: dict[str, Any]) -> str:
    """What makes two runs the same run: a resumed evaluation reuses a journaled record with this key."""
    return json.dumps([experiment, value, seed, scenario], sort_keys=True)


def record_key(record: Mapping[str, Any]) -> str | None:
    if "scenario" not in record:
        return None
    return task_key(record["experiment"], record["value"], record["seed"], record["scenario"])


def read_journal(path: Path) -> dict[str, EvalRun]:
    """Finished runs of an earlier (interrupted) evaluation, by task key.

    A line cut short by the interruption is skipped with a warning, never fatal.
    """
    found: dict[str, EvalRun] = {}
    if not path.is_file():
        return found
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            key = record_key(record)
        except (json.JSONDecodeError, KeyError, TypeError):
            log.warning("%s line %d is not a complete run record; it will be run again", path, n)
            continue
        if key is None:
            continue
        if record.get("interrupted"):  # journaled by an older version: a run cut short is not a result
            log.warning("%s line %d is a run cut short by an interruption; it will be run again", path, n)
            continue
        found[key] = record
    return found


class Runner:
    """A process pool that records every finished run to a JSON-lines journal as it arrives.

    Only runs that ended on their own are journaled: a run cut short by Ctrl-C is dropped (and rerun on
    ``--resume``).

    The journal makes an interrupted evaluation keep its finished runs; ``reuse`` (journaled records
    by task key) lets a resumed evaluation skip them: they are neither run nor journaled again.
    """

    def __init__(self, spec: DriverSpec, workers: int, journal: Path,
                 on_result: Callable[[EvalRun], None] | None = None,
                 reuse: dict[str, EvalRun] | None = None) -> None:
        self.spec = spec
        self.journal = journal
        self.on_result = on_result
        self.records: list[EvalRun] = []
        self.reused = 0
        self.workers = max(1, workers)  # runs at once (a cluster backend sets its own)
        self.retried: list[Retry] = []  # runs a backend retried after a failure, for the record
        self._reuse = dict(reuse or {})
        self._lock = threading.Lock()
        self.failure: OSError | None = None  # the first journal write that failed: the evaluation stops
        self._pool = self._start(workers)

    def _start(self, workers: int) -> Any:
        """The execution engine (here a local process pool); a backend subclass starts its own."""
        import cv2

        # OpenCV's thread pool, once started in this process, hangs a forked worker in its first parallel call;
        # one thread here leaves the workers nothing to inherit (they run one thread each anyway)
        cv2.setNumThreads(1)
        return ProcessPoolExecutor(max_workers=max(1, workers), initializer=_init_worker)

    def _launch(self, task: Task) -> Future[EvalRun]:
        """Start one run on the engine; the future's result is the run record."""
        return self._pool.submit(run_task, self.spec, task)

    def submit(self, task: Task) -> Future[EvalRun]:
        done = self._reuse.pop(task_key(task.experiment, task.value, task.seed, task.scenario), None)
        if done is not None:
            future: Future[EvalRun] = Future()
            future.set_result(done)
            with self._lock:
                self.reused += 1
                self.records.append(done)
            if self.on_result:
                self.on_result(done)
            return future
        if self.failure is not None:  # the journal cannot be written (a full disk): start nothing new
            raise self.failure
        future = self._launch(task)
        outer: Future[EvalRun] = Future()  # resolves once the run is journaled; a journal error is its exception
        future.add_done_callback(lambda inner: self._record(inner, outer))
        return outer

    def run(self, tasks: Iterable[Task]) -> list[EvalRun]:
        futures = [self.submit(t) for t in tasks]
        return [f.result() for f in futures]

    def _record(self, inner: Future[EvalRun], outer: Future[EvalRun]) -> None:
        if not pass_on(inner, outer):
            return
        try:
            self._keep(inner.result())
        except OSError as exc:
            self.failure = self.failure or exc
            outer.set_exception(exc)
            return
        outer.set_result(inner.result())

    def _keep(self, record: EvalRun) -> None:
        """Journal a finished run and tell ``on_result``."""
        if record.get("interrupted"):
            # Ctrl-C reaches the workers too, and the simulator returns the run so far: eta 0 for a run
            # that never failed. Neither journaled (a resume would reuse it) nor counted as a result.
            return
        with self._lock:
            append_record(self.journal, (json.dumps(record) + "\n").encode("utf-8"))  # whole, or raises
            self.records.append(record)
        if self.on_result:
            self.on_result(record)

    def close(self, cancel: bool = False) -> None:
        self._pool.shutdown(wait=not cancel, cancel_futures=cancel)


def pass_on(inner: Future[EvalRun], outer: Future[EvalRun]) -> bool:
    """Give ``outer`` the cancellation or the exception of the finished ``inner``; True if it has a result."""
    if inner.cancelled():
        outer.cancel()
        return False
    if inner.exception() is not None:
        outer.set_exception(inner.exception())
        return False
    return True


def spec_dict(spec: DriverSpec) -> dict[str, object]:
    return asdict(spec)
