"""Plan and execute the robustness suite for one model and one behavior.

Phase 1 runs every eta experiment over K seeds at once; phase 2 runs the range searches
concurrently (each stepping outward one value at a time, so no run is wasted past a failure).
"""

from __future__ import annotations

import logging
import statistics
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from protocol.facts import DEPLOY_SPEED_KMH
from tools.evaluate.evalrecord import EvalRun
from tools.evaluate.experiments import (
    EXPERIMENTS,
    PAPER_EXPERIMENTS,
    SETUPS,
    AxisValue,
    Experiment,
    is_autonomous,
    run_eta,
)
from tools.evaluate.runner import Runner, Task
from tools.evaluate.search import SearchResult, step_outward
from tools.sim.render.camera import DEFAULT_RIG
from tools.sim.vehicle.kinematic import VEHICLE_KINDS

log = logging.getLogger(__name__)


@dataclass
class SuiteConfig:
    behavior: str = "simplistic"
    seeds: int = 3
    base_seed: int = 0
    laps: int = 1
    speed_limit_kmh: float = DEPLOY_SPEED_KMH
    experiments: tuple[str, ...] = PAPER_EXPERIMENTS  # unseen_worlds only when asked for
    track: str | None = None  # override the behavior's track (e.g. a short test track)
    map_dir: str | None = None
    vehicle: str = VEHICLE_KINDS[0]  # the car model (ScenarioConfig.vehicle)
    camera: str = DEFAULT_RIG  # the camera rig (ScenarioConfig.camera): rbc eval passes the model's
    overrides: dict[str, Any] = field(default_factory=dict)  # extra ScenarioConfig fields
    worlds: tuple[tuple[int, str], ...] = ()  # (seed, track file) of the unseen_worlds experiment


class SearchStopped(Exception):
    """Raised inside a range search once the evaluation is being interrupted."""


def base_scenario(cfg: SuiteConfig) -> dict[str, Any]:
    setup = SETUPS[cfg.behavior]
    scenario = {"track": cfg.track or setup.track, "laps": cfg.laps, "cones": setup.cones,
                "cone_seed": setup.cone_seed, "speed_limit_kmh": cfg.speed_limit_kmh, "vehicle": cfg.vehicle,
                "camera": cfg.camera}
    scenario.update(cfg.overrides)
    return scenario


def _scenario_for(exp: Experiment, value: AxisValue, cfg: SuiteConfig, seed: int) -> dict[str, Any]:
    scenario = {**base_scenario(cfg), **exp.fixed, "seed": seed, "realtime": exp.realtime, "spawn_noise": True}
    if exp.parameter == "spawn_fraction":
        from tools.sim.track.files import load_track

        assert value is not None  # a fraction of the lap
        scenario["spawn_s"] = float(value) * load_track(scenario["track"]).length
    elif exp.parameter is not None:
        scenario[exp.parameter] = value
    return scenario


def _task(exp: Experiment, value: AxisValue, cfg: SuiteConfig, seed: int) -> Task:
    return Task(exp.key, cfg.behavior, value, seed, _scenario_for(exp, value, cfg, seed), cfg.map_dir)


def _world_task(exp: Experiment, seed: int, path: str, cfg: SuiteConfig) -> Task:
    """One run on a generated world, at the first seed (the nominal spawn pose); the document travels with it."""
    from tools.evaluate.worlds import track_doc

    scenario = {**base_scenario(cfg), "track": path, "seed": cfg.base_seed, "realtime": False, "spawn_noise": True}
    return Task(exp.key, cfg.behavior, seed, cfg.base_seed, scenario, cfg.map_dir, track_doc=track_doc(path))


def summarize_eta(records: Sequence[EvalRun]) -> dict[str, Any]:
    etas = [run_eta(r) for r in records]
    return {"mean": statistics.fmean(etas), "std": statistics.pstdev(etas) if len(etas) > 1 else 0.0,
            "n": len(etas), "etas": etas, "autonomous": sum(is_autonomous(r) for r in records)}


def max_runs(cfg: SuiteConfig) -> int:
    """The most runs the suite can take (range searches usually stop earlier): a progress bar's total."""
    chosen = [e for e in EXPERIMENTS if e.key in cfg.experiments and e.applies_to(cfg.behavior)]
    searched = any(e.measure in ("range", "max") for e in chosen)
    total = 0 if any(e.key == "no_variation" for e in chosen) or not searched else cfg.seeds
    for exp in chosen:
        if exp.measure == "worlds":
            total += len(cfg.worlds)
        elif exp.measure == "eta":
            total += len(exp.values) * cfg.seeds
        elif exp.measure == "range":
            total += round((exp.origin - exp.lower_cap) / exp.step) + round((exp.upper_cap - exp.origin) / exp.step)
        else:
            total += round((exp.upper_cap - exp.origin) / exp.step) + 1
    return total


def run_suite(cfg: SuiteConfig, runner: Runner, workers: int) -> dict[str, Any]:
    """Run the chosen experiments; return the per-experiment summary (records are in runner.records)."""
    chosen = [e for e in EXPERIMENTS if e.key in cfg.experiments and e.applies_to(cfg.behavior)]
    seeds = [cfg.base_seed + k for k in range(cfg.seeds)]
    summary: dict[str, Any] = {}

    # phase 1: eta experiments (no variation first: the ranges start from it)
    eta_exps = [e for e in chosen if e.measure == "eta"]
    if "no_variation" not in [e.key for e in eta_exps] and any(e.measure in ("range", "max") for e in chosen):
        eta_exps.insert(0, next(e for e in EXPERIMENTS if e.key == "no_variation"))
    futures = {(e.key, v, s): runner.submit(_task(e, v, cfg, s)) for e in eta_exps for v in e.values for s in seeds}
    world_exps = [e for e in chosen if e.measure == "worlds"]
    worlds = {(e.key, seed): runner.submit(_world_task(e, seed, path, cfg)) for e in world_exps
              for seed, path in cfg.worlds}
    for exp in eta_exps:
        summary[exp.key] = {"measure": "eta", "title": exp.title, "parameter": exp.parameter, "values": {
            str(v): summarize_eta([futures[(exp.key, v, s)].result() for s in seeds]) for v in exp.values}}
    if world_exps:
        from tools.evaluate.worlds import summarize_worlds

        for exp in world_exps:
            summary[exp.key] = summarize_worlds([worlds[(exp.key, seed)].result() for seed, _ in cfg.worlds])

    # phase 2: range searches, all directions concurrently, one step at a time each
    base = futures.get(("no_variation", None, cfg.base_seed))
    base_ok = base is not None and base.result()["autonomous"]
    searches: list[tuple[Experiment, str, float, float, float]] = []
    for exp in chosen:
        if exp.measure == "range":
            searches += [(exp, "lower", exp.origin, -exp.step, exp.lower_cap),
                         (exp, "upper", exp.origin, exp.step, exp.upper_cap)]
        elif exp.measure == "max":  # the origin itself is tested too
            searches.append((exp, "upper", exp.origin - exp.step, exp.step, exp.upper_cap))

    def search(item: tuple[Experiment, str, float, float, float]) -> tuple[str, str, SearchResult]:
        exp, side, origin, step, cap = item

        def evaluate(values):
            if stop.is_set():
                raise SearchStopped
            fs = [runner.submit(_task(exp, v, cfg, cfg.base_seed)) for v in values]
            return [f.result()["autonomous"] for f in fs]

        return exp.key, side, step_outward(evaluate, origin, step, cap, batch=1)

    range_results: dict[str, dict[str, SearchResult]] = {}
    stop = threading.Event()
    if searches:
        if not base_ok and any(s[0].measure == "range" for s in searches):
            log.warning("the no-variation run is not autonomous: ranges around it are empty")
        runnable = [s for s in searches if s[0].measure == "max" or base_ok]
        pool = ThreadPoolExecutor(max_workers=max(1, min(len(runnable) or 1, max(2, workers * 2))))
        try:
            for key, side, res in pool.map(search, runnable):
                range_results.setdefault(key, {})[side] = res
        except BaseException:  # Ctrl-C: stop every search at its next step, start nothing new
            stop.set()
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()
    for exp in chosen:
        if exp.measure not in ("range", "max"):
            continue
        sides = range_results.get(exp.key, {})
        entry: dict[str, Any] = {"measure": exp.measure, "title": exp.title, "parameter": exp.parameter,
                                 "origin": exp.origin, "step": exp.step, "unit": exp.unit,
                                 "caps": [exp.lower_cap, exp.upper_cap]}
        for side, res in sides.items():
            limit = res.limit
            if exp.measure == "max" and not (res.tried and res.tried[0][1]):
                limit = None  # the starting value itself failed
            entry[side] = {"limit": limit, "first_failure": res.first_failure, "hit_cap": res.hit_cap,
                           "tried": res.tried}
        if exp.measure == "range" and not base_ok:
            entry["empty"] = True
        summary[exp.key] = entry
    return summary


def with_behavior(cfg: SuiteConfig, behavior: str) -> SuiteConfig:
    return replace(cfg, behavior=behavior)


def ensure_dir(path: Path) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    return path
