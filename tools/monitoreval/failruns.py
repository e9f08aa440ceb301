"""``rbc monitor failures``: drive the steering model on training worlds, perturbed, degraded and nominal, and keep
every frame's input with the run's take-overs, one file per run, for the failure predictor to learn from
(:mod:`models.monitoring.failures`). A run already written for this model and code is kept: an interrupted
collection resumes, and each file is written through a temporary one."""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from models.monitoring.failures import SUFFIX, FailureRun, load_run, quantise, save_run
from protocol.codeversion import code_digest
from protocol.errors import BadValue
from tools.monitoreval.modelfiles import degraded_model, file_digest
from tools.monitoreval.runner import RUN_CODE
from tools.monitoreval.runset import RunSpec

if TYPE_CHECKING:
    from drive_server.serving.client_monitor import ClientMonitor, MonitorReading


class _Recording:
    """The driving monitor, keeping each input it is shown (quantised: 12 KB a frame for a 64x64 input)."""

    def __init__(self, primary: ClientMonitor) -> None:
        self.primary = primary
        self.inputs: list[np.ndarray] = []

    def observe(self, x: np.ndarray, steering: float | None = None) -> MonitorReading | None:
        self.inputs.append(quantise(x[0]))
        return self.primary.observe(x, steering)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.primary, name)


def drive_recorded(spec: RunSpec, model: Path) -> FailureRun:
    """One run of ``model`` (``--monitor warn``, its own monitor in the loop) with every frame's input kept."""
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
    from tools.sim.driving.drivers import OnnxDriver, Scene
    from tools.sim.driving.model_rig import model_rig
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.session import run_scenario
    from tools.sim.worldgen import resolve_track_name

    class Driver(OnnxDriver):
        def start(self, scene: Scene) -> None:
            super().start(scene)
            if self.monitor is not None:
                self.monitor = _Recording(self.monitor)  # type: ignore[assignment]

    driver = Driver(model, monitor=MonitorPolicy(mode=MonitorMode.WARN))
    if driver.monitor is None:
        raise BadValue(f"{model.name} carries no monitor: its input is read through one (attach any, e.g. "
                       "rbc monitor fit --score shift)")
    config = ScenarioConfig(track=resolve_track_name(spec.track), seed=spec.seed, light_intensity=spec.light_intensity,
                            light_direction_deg=spec.light_direction_deg, yaw_offset_deg=spec.yaw_offset_deg,
                            cones=spec.cones, cone_seed=spec.seed, camera=model_rig(model))
    result = run_scenario(config, driver)
    recorder = driver.monitor
    inputs = np.stack(recorder.inputs) if isinstance(recorder, _Recording) and recorder.inputs else None
    if inputs is None:
        raise BadValue(f"{spec.name}: the run recorded no frame")
    t = np.array([when for when, _ in driver.readings], np.float32)
    takeovers = tuple((round(i.t, 3), str(i.cause)) for lap in result.laps for i in lap.interventions)
    return FailureRun(spec.name, inputs[:len(t)], t[:len(inputs)], takeovers,
                      {**spec.to_dict(), "seed_range": "train", "sim_time_s": result.sim_time_s})


def _one(spec: RunSpec, model: Path, folder: Path, key: dict[str, str]) -> tuple[str, int]:
    path = folder / f"{spec.name}{SUFFIX}"
    driven = degraded_model(model, folder / "models", spec.weight_noise, spec.seed) if spec.weight_noise else model
    run = drive_recorded(spec, driven)
    save_run(path, FailureRun(run.name, run.inputs, run.t, run.takeovers, {**run.meta, **key}))
    return spec.name, len(run.takeovers)


def collect_failures(specs: list[RunSpec], model: Path, out: Path, workers: int = 1,
                     progress: Callable[[int, int, str], None] | None = None) -> list[Path]:
    """Drive every spec not yet in ``out`` for this model and code; the run files, in ``specs``' order."""
    out.mkdir(parents=True, exist_ok=True)
    key = {"model_sha256": file_digest(model), "code": code_digest(*RUN_CODE, "tools.monitoreval.failruns")}
    todo = []
    for spec in specs:
        path = out / f"{spec.name}{SUFFIX}"
        if path.is_file():
            try:
                meta = load_run(path).meta
                if all(meta.get(k) == v for k, v in key.items()):
                    continue
            except ValueError:
                pass  # unreadable (cut off): driven again
        todo.append(spec)
    total, done = len(specs), len(specs) - len(todo)
    if progress is not None and done:
        progress(done, total, "already written")

    def finished(name: str, takeovers: int) -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total, f"{name} ({takeovers} take-overs)")

    if workers <= 1 or len(todo) <= 1:
        for spec in todo:
            finished(*_one(spec, model, out, key))
    else:
        context = multiprocessing.get_context("fork" if hasattr(os, "fork") else "spawn")
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
            futures = [pool.submit(_one, spec, model, out, key) for spec in todo]
            try:
                for future in concurrent.futures.as_completed(futures):
                    finished(*future.result())
            except BaseException:
                pool.shutdown(wait=False, cancel_futures=True)
                raise
    return [out / f"{spec.name}{SUFFIX}" for spec in specs]
