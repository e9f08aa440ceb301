"""Drive the benchmark's runs with the monitored model in-process (drive_server's own pipeline, the monitor in
``warn`` or ``act``), one journal line per finished run so an interrupted benchmark resumes where it stopped and
a resumed one equals a clean one. Each line is keyed on everything its result depends on: the run, the mode, the
model file's content, and the version of the code that drives and scores it (derived from its imports)."""

from __future__ import annotations

import hashlib
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
from tools.monitoreval.runset import RunSpec

if TYPE_CHECKING:
    from drive_server.serving.client_monitor import ClientMonitor, MonitorReading
    from drive_server.serving.monitor import MonitorGraph
    from tools.sim.driving.drivers import Scene

log = logging.getLogger(__name__)

JOURNAL = "runs.jsonl"
#: The modules whose code a run's result depends on (their imports are followed).
RUN_CODE = ("tools.monitoreval.runner", "tools.sim.driving.session", "tools.sim.driving.drivers",
            "drive_server.serving.pipeline")


def file_digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def degraded_model(src: Path, folder: Path, sigma: float, seed: int = 0) -> Path:
    """``src`` with Gaussian noise on every weight tensor (sigma times the tensor's std), its metadata and monitor
    kept: a model that drives worse on the same frames. Cached in ``folder`` by source content, sigma and seed."""
    import onnx
    from onnx import numpy_helper

    from protocol.runrecords import atomic_path

    dst = Path(folder) / f"{Path(src).stem}-noise{sigma:g}-s{seed}-{file_digest(src)}.onnx"
    if dst.is_file():
        return dst
    rng = np.random.default_rng(seed)
    proto = onnx.load(str(src))
    for tensor in proto.graph.initializer:
        w = numpy_helper.to_array(tensor)
        if w.dtype != np.float32 or w.size < 2:
            continue
        noisy = (w + rng.normal(0.0, sigma * float(w.std()), w.shape)).astype(np.float32)
        tensor.CopyFrom(numpy_helper.from_array(noisy, tensor.name))
    with atomic_path(dst) as tmp:
        onnx.save(proto, str(tmp))
    return dst


def check_checkpoint(served: Path, checkpoint: Path) -> None:
    """BadValue (one line) unless ``checkpoint`` can stand in for ``served`` under its monitor: another file that
    reads the same input (preprocessing contract ``rbc.preprocess``, input shape, camera rig), answers the mirror
    average alike (graph outputs :data:`~tools.monitoreval.candidates.MIRROR_HALVES`) and asks for the same serving
    settings (``rbc.serving``: gain, smoothing)."""
    from drive_server.serving.settings import SERVING_KEY, Serving
    from models.onnxfiles.onnx_metadata import read_steering_graph
    from tools.monitoreval.candidates import MIRROR_HALVES
    from tools.sim.driving.model_rig import model_rig

    name, hint = Path(checkpoint).name, "give a checkpoint of the served model's recipe, exported and mirrored alike"
    if file_digest(checkpoint) == file_digest(served):
        raise BadValue(f"checkpoint {name}: the served model {Path(served).name} itself", hint)
    a, b = read_steering_graph(served, BadValue), read_steering_graph(checkpoint, BadValue)
    if b.contract != a.contract or b.shape[1:] != a.shape[1:]:
        raise BadValue(f"checkpoint {name}: its preprocessing (rbc.preprocess, input shape) differs from "
                       f"{Path(served).name}'s", hint)
    if model_rig(checkpoint) != model_rig(served):
        raise BadValue(f"checkpoint {name}: trained for the {model_rig(checkpoint)} camera, {Path(served).name} for "
                       f"the {model_rig(served)} camera", hint)

    def mirrored(proto: Any) -> bool:
        return set(MIRROR_HALVES) <= {out for node in proto.graph.node for out in node.output}

    if mirrored(a.proto) != mirrored(b.proto):
        raise BadValue(f"checkpoint {name}: {'answers' if mirrored(b.proto) else 'does not answer'} the mirror "
                       f"average and {Path(served).name} {'does not' if mirrored(b.proto) else 'does'}",
                       "treat it as the served model was (rbc mirror)")
    try:
        settings = [Serving.from_json(g.meta.get(SERVING_KEY)) for g in (a, b)]
    except BadValue as exc:
        raise BadValue(f"checkpoint {name} or {Path(served).name}: {exc}") from None
    if settings[0] != settings[1]:
        raise BadValue(f"checkpoint {name}: served with {settings[1].describe() or 'nothing asked'}, "
                       f"{Path(served).name} with {settings[0].describe() or 'nothing asked'}", hint)


def checkpoint_epochs(checkpoint: Path) -> float:
    """How many epochs ``checkpoint`` was trained (its record's exported epoch, else its epochs); 0 if it cannot
    say."""
    from models.onnxfiles.onnx_metadata import read_steering_graph

    info = read_steering_graph(checkpoint, BadValue).info
    for key in ("exported_epoch", "epochs"):
        value = info.get(key)
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
    return 0.0


def undertrained_model(checkpoint: Path, served: Path, folder: Path) -> Path:
    """``checkpoint`` (checked by :func:`check_checkpoint`) carrying the served model's monitor: every ``rbc.monitor``
    metadata key of ``served`` in place of any the checkpoint has, the rest of the checkpoint as it is. Cached in
    ``folder`` by both files' content, so a run of it is keyed by the checkpoint's content and the monitor's."""
    import onnx

    from drive_server.serving.monitor import MONITOR_KEY
    from protocol.runrecords import atomic_path

    check_checkpoint(served, checkpoint)
    dst = Path(folder) / f"{Path(checkpoint).stem}-watched-{file_digest(checkpoint)}-{file_digest(served)}.onnx"
    if dst.is_file():
        return dst

    def monitor_key(key: str) -> bool:
        return key == MONITOR_KEY or key.startswith(MONITOR_KEY + ".")

    proto = onnx.load(str(checkpoint))
    served_meta = [(m.key, m.value) for m in onnx.load(str(served)).metadata_props if monitor_key(m.key)]
    kept = [(m.key, m.value) for m in proto.metadata_props if not monitor_key(m.key)]
    del proto.metadata_props[:]
    for key, value in kept + served_meta:
        proto.metadata_props.add(key=key, value=value)
    dst.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(dst) as tmp:
        onnx.save(proto, str(tmp))
    return dst


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


def drive(spec: RunSpec, model: Path, mode: str, shadows: tuple[Path, ...] = ()) -> dict[str, Any]:
    """One run: the per-frame monitor state and one-second mean, the take-overs, and the lap's figures; each
    of ``shadows`` (model files with another monitor for the same steering input) scored on every frame too."""
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
    from drive_server.serving.model import SteeringModel
    from tools.sim.driving.drivers import OnnxDriver
    from tools.sim.driving.model_rig import model_rig
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.session import run_scenario
    from tools.sim.worldgen import resolve_track_name

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
    config = ScenarioConfig(track=resolve_track_name(spec.track), seed=spec.seed, light_intensity=spec.light_intensity,
                            light_direction_deg=spec.light_direction_deg, yaw_offset_deg=spec.yaw_offset_deg,
                            cones=spec.cones, cone_seed=spec.seed, camera=model_rig(model))
    result = run_scenario(config, driver)
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
