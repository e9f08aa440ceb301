"""Drive the benchmark's runs with the monitored model in-process (drive_server's own pipeline, the monitor in
``warn`` or ``act``), one journal line per finished run so an interrupted benchmark resumes where it stopped and
a resumed one equals a clean one. Each line is keyed on everything its result depends on: the run, the mode, the
model file's content, and the version of the code that drives and scores it (derived from its imports)."""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from protocol.codeversion import code_digest
from protocol.errors import BadValue
from tools.monitoreval.modelfiles import degraded_model, file_digest, undertrained_model
from tools.monitoreval.runset import RunSpec

if TYPE_CHECKING:
    from drive_server.serving.client_monitor import ClientMonitor, MonitorReading
    from drive_server.serving.monitor import MonitorGraph
    from tools.sim.driving.drivers import Scene
    from tools.sim.driving.scenario import ScenarioConfig

log = logging.getLogger(__name__)

JOURNAL = "runs.jsonl"
#: The modules whose code a run's result depends on (their imports are followed).
RUN_CODE = ("tools.monitoreval.runner", "tools.monitoreval.modelfiles", "tools.sim.driving.session",
            "tools.sim.driving.drivers", "drive_server.serving.pipeline")


@dataclass(frozen=True)
class RunKey:
    spec: RunSpec
    mode: str
    model: str  # content digest of the file driven (the degraded or under-trained copy for a degraded run)
    code: str
    shadows: tuple[str, ...] = ()  # content digests of the monitors scored in the shadow of the driving one

    def text(self) -> str:
        return json.dumps({"spec": self.spec.to_dict(), "mode": self.mode, "model": self.model, "code": self.code,
                           "shadows": list(self.shadows)}, sort_keys=True)


class _Shadowed:
    """The driving monitor, and other monitors scored on the very same inputs (so monitors are compared on one
    drive, not on two drives that differ); only the first acts."""

    def __init__(self, primary: ClientMonitor, shadows: list[MonitorGraph]) -> None:
        self.primary, self.shadows = primary, shadows
        self.scores: list[list[float]] = [[] for _ in shadows]

    def observe(self, x: np.ndarray, steering: float | None = None) -> MonitorReading | None:
        reading = self.primary.observe(x, steering)
        for graph, out in zip(self.shadows, self.scores, strict=True):
            out.append(graph.score(x, steering) if graph.wants_steering else graph.score(x))
        return reading

    def __getattr__(self, name: str) -> Any:  # last, failed, state: the primary's
        return getattr(self.primary, name)


def scenario(spec: RunSpec, camera: str) -> ScenarioConfig:
    """The simulator's set-up of one run. The spawn is jittered by the run's seed (``spawn_noise``): without it two
    runs of one setting on a built-in track would be the same drive, and count the same failures twice."""
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.worldgen import resolve_track_name

    return ScenarioConfig(track=resolve_track_name(spec.track), seed=spec.seed, spawn_noise=True,
                          light_intensity=spec.light_intensity, light_direction_deg=spec.light_direction_deg,
                          yaw_offset_deg=spec.yaw_offset_deg, cones=spec.cones, cone_seed=spec.seed, camera=camera)


def drive(spec: RunSpec, model: Path, mode: str, shadows: tuple[Path, ...] = ()) -> dict[str, Any]:
    """One run: the per-frame monitor state and one-second mean, the take-overs, and the lap's figures; each
    of ``shadows`` (model files with another monitor for the same steering input) scored on every frame too."""
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
    from drive_server.serving.model import SteeringModel
    from tools.sim.driving.drivers import OnnxDriver
    from tools.sim.driving.model_rig import model_rig
    from tools.sim.driving.session import run_scenario

    graphs = []
    for path in shadows:
        found = SteeringModel(path).monitor()
        if found is None:
            raise BadValue(f"{path.name} carries no monitor")
        graphs.append(found[1])

    class Driver(OnnxDriver):
        def start(self, scene: Scene) -> None:
            super().start(scene)
            if self.monitor is not None and graphs:
                self.monitor = _Shadowed(self.monitor, graphs)  # type: ignore[assignment]

    driver = Driver(model, monitor=MonitorPolicy(mode=MonitorMode(mode)))
    if driver.monitor is None:
        raise BadValue(f"{model.name} carries no monitor (attach one with rbc monitor fit)")
    result = run_scenario(scenario(spec, model_rig(model)), driver)
    t = [round(when, 3) for when, _ in driver.readings]
    level = "".join(str(int(r.level)) if r is not None else "0" for _, r in driver.readings)
    mean = [round(r.mean, 6) if r is not None else None for _, r in driver.readings]
    lap = result.laps[0] if result.laps else None
    return {"t": t, "level": level, "mean": mean,
            "takeovers": [[round(i.t, 3), str(i.cause)] for lap_ in result.laps for i in lap_.interventions],
            "sim_time_s": result.sim_time_s, "eta": result.mean_eta, "completed": result.completed,
            "lap_time_s": lap.lap_time_s if lap else None, "mean_speed_kmh": lap.mean_speed_kmh if lap else None,
            "monitor_failed": driver.monitor.failed if driver.monitor is not None else None,
            "shadows": {path.name: [round(float(v), 6) for v in values] for path, values
                        in zip(shadows, driver.monitor.scores if isinstance(driver.monitor, _Shadowed) else [],
                               strict=False)}}


class Journal:
    """Finished runs by key; lines that no longer load are counted and reported, never silently dropped."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.done: dict[str, dict[str, Any]] = {}
        if not path.is_file():
            return
        bad = 0
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                entry = json.loads(line)
                self.done[entry["key"]] = entry["run"]
            except (ValueError, KeyError, TypeError):
                bad += 1
        if bad:
            log.warning("%s: %d line(s) could not be read (a run cut off mid-write?); those runs are driven again",
                        path, bad)

    def add(self, key: str, run: dict[str, Any]) -> None:
        self.done[key] = run
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a", encoding="utf-8") as fh:
            fh.write(json.dumps({"key": key, "run": run}) + "\n")


def drive_all(specs: list[RunSpec], model: Path, modes: tuple[str, ...], out: Path,
              progress: Callable[[int, int, str], None] | None = None,
              workers: int = 1, shadows: tuple[Path, ...] = (),
              rescore: bool = False,
              checkpoints: tuple[Path, ...] = ()) -> list[tuple[RunSpec, str, dict[str, Any]]]:
    """Every spec in every mode, resuming from ``out``'s journal; (spec, mode, run) in a fixed order whatever
    ``workers`` (processes driving runs side by side; each run is deterministic, so the order of finishing
    changes nothing but the journal's line order).

    ``rescore``: drive nothing; take each run from the journal whatever code drove it (its other key parts must
    match), for new scoring rules or tables over the same drives. A run the journal lacks is an error.

    ``checkpoints``: the under-trained checkpoints that specs name (by content digest); each is driven as a copy
    with the served model's monitor (:func:`undertrained_model`).
    """
    import concurrent.futures
    import multiprocessing

    journal = Journal(out / JOURNAL)
    code = code_digest(*RUN_CODE)
    if rescore:
        by_rest: dict[str, tuple[str, dict[str, Any]]] = {}
        for key, run in journal.done.items():
            parts = json.loads(key)
            by_rest[json.dumps({k: v for k, v in parts.items() if k != "code"}, sort_keys=True)] = (parts["code"], run)
    models = out / "models"
    shadow_digests = tuple(file_digest(p) for p in shadows)
    todo: dict[str, tuple[RunSpec, Path, str]] = {}
    order = []
    by_digest = {file_digest(p): p for p in checkpoints}
    watched: dict[str, Path] = {}  # checkpoint digest -> its copy with the served monitor
    for spec in specs:
        if spec.checkpoint:
            if spec.checkpoint not in by_digest:
                raise BadValue(f"{spec.name}: no checkpoint given with content {spec.checkpoint}")
            if spec.checkpoint not in watched:
                watched[spec.checkpoint] = undertrained_model(by_digest[spec.checkpoint], model, models)
            path = watched[spec.checkpoint]
        elif spec.weight_noise:
            path = degraded_model(model, models, spec.weight_noise, spec.seed)
        else:
            path = model
        digest = file_digest(path)
        for mode in modes:
            key = RunKey(spec, mode, digest, code, shadow_digests).text()
            if rescore:
                rest = json.dumps({k: v for k, v in json.loads(key).items() if k != "code"}, sort_keys=True)
                if rest not in by_rest:
                    raise BadValue(f"{out / JOURNAL} has no run {spec.name} ({mode}) of this model to score again",
                                   "drop --rescore to drive it")
                key = RunKey(spec, mode, digest, by_rest[rest][0], shadow_digests).text()
            order.append((spec, mode, key))
            if key not in journal.done:
                todo[key] = (spec, path, mode)
    total, done = len(order), len(order) - len(todo)
    if progress is not None and done:
        progress(done, total, "from the journal")

    def finished(key: str, run: dict[str, Any]) -> None:
        nonlocal done
        journal.add(key, run)
        done += 1
        if progress is not None:
            spec, _, mode = todo[key]
            progress(done, total, f"{spec.name} ({mode})")

    if workers <= 1 or len(todo) <= 1:
        for key, (spec, path, mode) in todo.items():
            finished(key, drive(spec, path, mode, shadows))
    else:
        import cv2

        cv2.setNumThreads(1)  # a forked worker hangs in OpenCV's thread pool if this process started one
        context = multiprocessing.get_context("fork" if hasattr(os, "fork") else "spawn")
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
            futures = {pool.submit(drive, spec, path, mode, shadows): key for key, (spec, path, mode) in todo.items()}
            try:
                for future in concurrent.futures.as_completed(futures):
                    finished(futures[future], future.result())
            except BaseException:  # a failed run or Ctrl-C: the runs not started are not waited for
                pool.shutdown(wait=False, cancel_futures=True)
                raise
    return [(spec, mode, journal.done[key]) for spec, mode, key in order]
