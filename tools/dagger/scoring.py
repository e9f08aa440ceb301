"""Score one round's model as ``rbc eval`` does: the same runs, the same journal, the same eta (paper Eq. 2).

Every run goes through :mod:`tools.evaluate` unchanged: its runner drives the model in-process through
drive_server's pipeline (two frames in flight, as Unity), one lap per world or track at the nominal spawn (seed
0), and :func:`tools.evaluate.worlds.summarize_worlds` aggregates the unseen worlds (mean, std, worst world, runs
without a take-over). The built-in tracks are ``no_variation`` runs with the track overridden; Table 9's
orientation and light rows are ``rbc eval``'s own range searches on lake. Finished runs are journaled in
``runs.jsonl`` as they arrive, so a killed evaluation reuses them on resume and gives the clean run's figures.
"""

from __future__ import annotations

import json
import logging
import statistics
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from protocol.runrecords import file_sha256, read_json, write_json, write_text
from tools.dagger.config import PERTURBATIONS, DaggerConfig
from tools.dagger.records import RangeScore, RoundScores, TrackScore
from tools.evaluate.evalrecord import EvalRun
from tools.evaluate.experiments import is_autonomous, run_eta
from tools.evaluate.journal import run_code
from tools.evaluate.runner import DriverSpec, Runner, read_journal
from tools.evaluate.suite import SuiteConfig, run_suite
from tools.sim.driving.rules import TARGET_ETA

log = logging.getLogger(__name__)

JOURNAL = "runs.jsonl"
IDENTITY = "journal.json"


def _journal_for(model: Path, folder: Path) -> Path:
    """``folder``'s journal, emptied (kept as runs.previous.jsonl) unless it was written for this model file and
    this code (``journal.json``): a round's model made again scores afresh."""
    journal, identity_file = folder / JOURNAL, folder / IDENTITY
    identity = {"model_sha256": file_sha256(model), "code": run_code()}
    if journal.is_file() and (not identity_file.is_file() or read_json(identity_file) != identity):
        journal.replace(folder / "runs.previous.jsonl")
        log.warning("%s was written for another model or code: scored afresh (kept as runs.previous.jsonl)", journal)
    write_json(identity_file, identity)
    return journal


def runs_planned(config: DaggerConfig) -> int:
    """The runs of one evaluation, without the range searches (whose length depends on the model)."""
    return config.eval_worlds + len(config.tracks)


def _interventions(record: Mapping[str, Any]) -> int:
    return sum(lap.get("n_interventions", len(lap.get("interventions") or [])) for lap in record["laps"])


def evaluate_model(model: Path, folder: Path, config: DaggerConfig, worlds: list[tuple[int, str]], workers: int = 1,
                   on_result: Callable[[EvalRun], None] | None = None) -> RoundScores:
    """Score ``model`` on ``worlds`` (seed, track file), ``config.tracks`` and (``config.perturbations``) Table 9's
    orientation and light rows; the runs are journaled in ``folder/runs.jsonl`` and reused from there."""
    from tools.sim.driving.model_rig import model_rig

    folder.mkdir(parents=True, exist_ok=True)
    journal = _journal_for(model, folder)
    spec = DriverSpec(model=str(model))
    rig = model_rig(model)
    base = SuiteConfig(behavior="simplistic", seeds=1, base_seed=0, laps=config.laps,
                       speed_limit_kmh=config.speed_limit_kmh, camera=rig, map_dir=str(folder / "failures"))

    def suite(**changes: object) -> dict[str, Any]:
        reuse = read_journal(journal)
        # keep only whole lines: a run cut short by a kill is driven again and appended after them
        write_text(journal, "".join(json.dumps(r) + "\n" for r in reuse.values()))
        runner = Runner(spec, workers, journal, on_result=on_result, reuse=reuse)
        try:
            cfg = SuiteConfig(**{**vars(base), **changes})
            return run_suite(cfg, runner, runner.workers) | {"_records": list(runner.records)}
        finally:
            runner.close()

    result: RoundScores = {"camera_rig": rig}
    if worlds:
        summary = suite(experiments=("unseen_worlds",), worlds=tuple(worlds))
        entry = summary["unseen_worlds"]
        result["worlds"] = {
            "n": entry["n"], "mean": round(entry["mean"], 3), "std": round(entry["std"], 3),
            "worst": entry["worst"], "autonomous": entry["autonomous"],
            "at_target": sum(w["eta"] >= TARGET_ETA for w in entry["worlds"]),
            "takeovers": sum(w["interventions"] for w in entry["worlds"]),
            "per_world": [{"seed": w["seed"], "eta": round(w["eta"], 3), "takeovers": w["interventions"]}
                          for w in entry["worlds"]]}
    tracks: dict[str, TrackScore] = {}
    for track in config.tracks:
        summary = suite(experiments=("no_variation",), track=track)
        record = summary["_records"][0]  # driven now or reused from the journal
        tracks[track] = {"eta": round(run_eta(record), 3), "takeovers": _interventions(record),
                         "autonomous": is_autonomous(record)}
    result["tracks"] = tracks
    if config.perturbations:
        summary = suite(experiments=PERTURBATIONS)
        result["perturbations"] = {key: _range(summary[key]) for key in PERTURBATIONS if key in summary}
    etas = ([w["eta"] for w in result["worlds"]["per_world"]] if worlds else []) + [t["eta"] for t in tracks.values()]
    result["all"] = {"runs": len(etas), "mean": round(statistics.fmean(etas), 3), "worst": round(min(etas), 3),
                     "takeovers": (result["worlds"]["takeovers"] if worlds else 0)
                     + sum(t["takeovers"] for t in tracks.values())}
    return result


def _range(entry: dict[str, Any]) -> RangeScore:
    """A range search's result as Table 9 prints it: the autonomous range around the default (None: empty)."""
    if entry.get("empty"):
        return {"lower": None, "upper": None, "unit": entry["unit"], "empty": True, "text": "none"}
    from tools.evaluate.report import format_cell

    lower, upper = entry.get("lower") or {}, entry.get("upper") or {}
    return {"unit": entry["unit"], "text": format_cell(entry),
            "lower": _offset(lower.get("limit"), entry["origin"]), "lower_at_cap": bool(lower.get("hit_cap")),
            "upper": _offset(upper.get("limit"), entry["origin"]), "upper_at_cap": bool(upper.get("hit_cap"))}


def _offset(limit: float | None, origin: float) -> float | None:
    return None if limit is None else round(limit - origin, 6)
