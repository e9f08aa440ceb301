"""Reinforcement learning, behavioral cloning, DAgger and the expert on the same held-out worlds, scored alike.

``python -m tools.dagger.rlcompare --out DIR --ppo runs/ppo --onnx BC=M.onnx --onnx DAgger=M.onnx --expert`` drives
every policy one lap on each of the unseen evaluation worlds (1,000,000 on, ``--worlds N``, generated once into
``DIR/worlds``) and on each ``--tracks`` track, at seed 0 (the nominal spawn), through ``rbc eval``'s runner and
referee: a take-over puts the car back on the road and driving goes on, and each lap's degree of autonomy is the
paper's, eta = 1 - take-overs x 6 s / elapsed. ONNX models are ``rbc eval``'s own runs (the same tasks, driver and
record: ``rbc eval --experiments unseen_worlds`` gives the same figure per world); the PPO policy and the expert
drive the same runs (:mod:`tools.envs.policydrivers` says how and why). Each policy's runs are journaled in
``DIR/NAME/runs.jsonl`` and reused by a rerun for the same file and code. It writes ``DIR/comparison.json`` (the
seed, the code version, the worlds, and per policy every world's eta and take-overs, the mean, the worst world
and the worlds at 95 % or better) and prints the table.
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import replace
from pathlib import Path

from protocol.errors import BadValue
from tools.dagger.rlrecord import Comparison, PolicyScores, TrackScore
from tools.envs.policydrivers import PolicySpec, policy_driver
from tools.evaluate.evalrecord import EvalRun
from tools.evaluate.experiments import is_autonomous, run_eta
from tools.evaluate.runner import DriverSpec, Runner, Task, read_journal
from tools.sim.driving.rules import TARGET_ETA

log = logging.getLogger(__name__)

#: The built-in tracks driven beside the worlds by default (the DAgger comparison's).
DEFAULT_TRACKS = ("lake", "mountain")
#: The seed of every run: the nominal spawn, as rbc eval's unseen_worlds and rbc dagger's scoring.
SEED = 0
RECORD = "comparison.json"


def run_policy_task(policy: PolicySpec, task: Task) -> EvalRun:
    """One of ``rbc eval``'s runs driven by ``policy``: an ONNX model exactly as ``rbc eval`` drives it
    (:func:`tools.evaluate.runner.run_task`), any other policy through :func:`policy_driver`, with the same record.
    The expert's runs render no frames (it steers from the ground truth; the drive is the same)."""
    import cv2

    from tools.evaluate.runner import run_task
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.session import run_scenario

    if policy.kind == "onnx":
        return run_task(DriverSpec(model=policy.path), task)
    cv2.setNumThreads(1)
    config = ScenarioConfig(**task.scenario)
    started = time.perf_counter()
    result = run_scenario(config, policy_driver(policy, config), render=policy.kind != "expert")
    record: EvalRun = {"experiment": task.experiment, "behavior": task.behavior, "value": task.value,
                       "seed": task.seed, "wall_time_s": round(time.perf_counter() - started, 3), **result.to_dict(),
                       "scenario": task.scenario}
    record["autonomous"] = is_autonomous(record)
    return record


class PolicyRunner(Runner):
    """``rbc eval``'s runner (process pool, journal, reuse) with each run driven by :func:`run_policy_task`."""

    def __init__(self, policy: PolicySpec, workers: int, journal: Path,
                 on_result: Callable[[EvalRun], None] | None = None, reuse: dict[str, EvalRun] | None = None) -> None:
        self.policy = policy
        # the runner's spec names the file for the record; _launch drives the policy itself
        super().__init__(DriverSpec(model=policy.path or policy.name), workers, journal, on_result, reuse)

    def _launch(self, task: Task) -> Future[EvalRun]:
        return self._pool.submit(run_policy_task, self.policy, task)


def policy_rig(policy: PolicySpec) -> str:
    """The camera rig a policy learnt: an ONNX model's record, a PPO run's environment, the default for the expert."""
    from tools.sim.render.camera import DEFAULT_RIG

    if policy.kind == "onnx":
        from tools.sim.driving.model_rig import model_rig

        return model_rig(policy.path or "")
    if policy.kind == "ppo":
        from tools.envs.policydrivers import ppo_env_config

        return ppo_env_config(policy.path or "").camera
    return DEFAULT_RIG


def _journal(policy: PolicySpec, folder: Path) -> dict[str, EvalRun]:
    """The runs of an earlier comparison of this policy file with this code, to reuse; any other journal is kept
    aside as runs.previous.jsonl."""
    from protocol.codeversion import code_digest
    from protocol.runrecords import file_sha256, read_json, write_json, write_text
    from tools.evaluate.journal import run_code

    folder.mkdir(parents=True, exist_ok=True)
    journal, identity_file = folder / "runs.jsonl", folder / "journal.json"
    file = policy.model_file
    recipe = file.parent / "recipe.json" if file is not None and policy.kind == "ppo" else None  # what it observes
    identity = {"kind": policy.kind, "sha256": file_sha256(file) if file is not None else None,
                "recipe_sha256": file_sha256(recipe) if recipe is not None and recipe.is_file() else None,
                "code": run_code(), "policy_code": code_digest("tools.envs.policydrivers")}
    if journal.is_file() and (not identity_file.is_file() or read_json(identity_file) != identity):
        journal.replace(folder / "runs.previous.jsonl")
        log.info("%s was written for another policy file or code: driven afresh", journal)
    write_json(identity_file, identity)
    reuse = read_journal(journal)
    write_text(journal, "".join(json.dumps(r) + "\n" for r in reuse.values()))  # whole lines only
    return reuse


def _takeovers(record: EvalRun) -> int:
    return sum(lap.get("n_interventions", len(lap.get("interventions") or [])) for lap in record["laps"])


def score_policy(policy: PolicySpec, folder: Path, worlds: Sequence[tuple[int, str]], tracks: Sequence[str],
                 workers: int = 1) -> PolicyScores:
    """One lap per world and per track at seed 0, as ``rbc dagger`` scores a round (``rbc eval``'s unseen_worlds and
    no_variation runs, behavior simplistic); the policy's scores."""
    from tools.evaluate.suite import SuiteConfig, run_suite

    rig = policy_rig(policy)
    base = SuiteConfig(behavior="simplistic", seeds=1, base_seed=SEED, laps=1, camera=rig, worlds=tuple(worlds))
    # the worlds in one pool, then each track in its own, as rbc dagger scores a round
    suites = ([replace(base, experiments=("unseen_worlds",))] if worlds else []) + [
        replace(base, track=track, experiments=("no_variation",)) for track in tracks]
    reuse = _journal(policy, folder)
    scores: PolicyScores = {"name": policy.name, "kind": policy.kind, "path": policy.path, "camera_rig": rig}
    track_scores: dict[str, TrackScore] = {}
    for cfg in suites:
        runner = PolicyRunner(policy, workers, folder / "runs.jsonl", reuse=reuse)
        try:
            summary = run_suite(cfg, runner, runner.workers)
        finally:
            runner.close()
        if "unseen_worlds" in summary:
            entry = summary["unseen_worlds"]
            scores["worlds"] = {
                "n": entry["n"], "mean": round(entry["mean"], 3), "std": round(entry["std"], 3),
                "worst": entry["worst"], "autonomous": entry["autonomous"],
                "at_target": sum(w["eta"] >= TARGET_ETA for w in entry["worlds"]),
                "takeovers": sum(w["interventions"] for w in entry["worlds"]),
                "per_world": [{"seed": w["seed"], "eta": round(w["eta"], 3), "takeovers": w["interventions"]}
                              for w in entry["worlds"]]}
        for record in runner.records:
            if record["experiment"] == "no_variation":
                track_scores[str(cfg.track)] = {"eta": round(run_eta(record), 3), "takeovers": _takeovers(record),
                                                "autonomous": is_autonomous(record)}
    scores["tracks"] = {track: track_scores[track] for track in tracks}
    etas = [w["eta"] for w in scores.get("worlds", {}).get("per_world", [])] + [t["eta"] for t in track_scores.values()]
    scores["all"] = {"runs": len(etas), "mean": round(statistics.fmean(etas), 3), "worst": round(min(etas), 3),
                     "takeovers": scores.get("worlds", {}).get("takeovers", 0)
                     + sum(t["takeovers"] for t in track_scores.values())}
    return scores


def compare(policies: Sequence[PolicySpec], out: Path, worlds: int = 20, world_seed: int | None = None,
            world_config: str | None = None, tracks: Sequence[str] = DEFAULT_TRACKS,
            workers: int = 1) -> Comparison:
    """Score every policy on the same worlds and tracks; write and return ``OUT/comparison.json``'s record."""
    from protocol.runrecords import code_version, write_json
    from tools.evaluate.journal import run_code
    from tools.evaluate.worlds import eval_world_seeds, write_eval_worlds
    from tools.sim.worldgen.config import WorldGenConfig, parse_world_config

    names = [p.name for p in policies]
    if not policies or len(set(names)) != len(names):
        raise BadValue("give each policy once, under its own name", "--ppo, --onnx NAME=M.onnx, --expert")
    if not worlds and not tracks:
        raise BadValue("nothing to drive: --worlds 0 and no --tracks")
    from tools.sim.track.files import get_track
    from tools.sim.worldgen.generate import resolve_track_name

    for track in tracks:  # a bad name fails here, in one line, before any run
        get_track(resolve_track_name(track))
    out.mkdir(parents=True, exist_ok=True)
    meta = (write_eval_worlds(out, eval_world_seeds(worlds, world_seed),
                              parse_world_config(world_config) if world_config else WorldGenConfig(), resume=True)
            if worlds else None)
    files = [(int(seed), path) for seed, path in meta["files"].items()] if meta else []
    record: Comparison = {
        "what": "every policy one lap per world and track at seed 0, rbc eval's referee and degree of autonomy",
        "seed": SEED, "code_version": code_version(), "run_code": run_code(), "target_eta": TARGET_ETA,
        "worlds": meta, "tracks": list(tracks), "policies": []}
    for policy in policies:
        log.info("%s (%s): %d worlds, %d tracks", policy.name, policy.kind, len(files), len(tracks))
        record["policies"].append(score_policy(policy, out / policy.name, files, tracks, workers))
        write_json(out / RECORD, record)
    write_json(out / RECORD, record)
    return record


def table(record: Comparison) -> str:
    """The comparison as a Markdown table: one row per policy."""
    tracks = record["tracks"]
    head = ["policy", "worlds: mean autonomy", "worst world", "worlds ≥ 95 %", "take-overs", *tracks]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for p in record["policies"]:
        w = p.get("worlds")
        cells = [f"{p['name']} ({p['kind']})"]
        cells += ([f"{w['mean']:.1f} %", f"{w['worst']['eta']:.1f} % ({w['worst']['seed']})",
                   f"{w['at_target']}/{w['n']}"] if w else ["-", "-", "-"])
        cells.append(str(p["all"]["takeovers"]))
        cells += [f"{p['tracks'][t]['eta']:.1f} %" for t in tracks]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def _named(value: str, default: str | None = None) -> tuple[str, str]:
    name, sep, path = value.partition("=")
    if not sep:
        if default is None:
            raise BadValue(f"give NAME=PATH, got {value!r}")
        return default, value
    if not name or not path:
        raise BadValue(f"give NAME=PATH, got {value!r}")
    return name, path


def parse_policies(ppo: Sequence[str], onnx: Sequence[str], expert: bool) -> list[PolicySpec]:
    """The policies of the command line: ``--ppo [NAME=]RUN`` (default name PPO), ``--onnx NAME=M.onnx``,
    ``--expert``; a missing file is one line."""
    policies: list[PolicySpec] = []
    for kind, values in (("ppo", ppo), ("onnx", onnx)):
        for value in values:
            name, path = _named(value, "PPO" if kind == "ppo" else None)
            policies.append(PolicySpec(name, kind, path))
            file = policies[-1].model_file
            if file is None or not file.is_file():
                raise BadValue(f"{name}: no such file {file}", "a PPO run folder holds model.zip" if kind == "ppo"
                               else "an ONNX model from rbc train or rbc dagger")
    if expert:
        policies.append(PolicySpec("expert", "expert"))
    return policies


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tools.dagger.rlcompare", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="folder for comparison.json, the worlds and each policy's runs")
    parser.add_argument("--ppo", action="append", default=[], metavar="[NAME=]RUN",
                        help="a PPO run folder (model.zip, recipe.json) or model.zip (repeat for more)")
    parser.add_argument("--onnx", action="append", default=[], metavar="NAME=M.onnx",
                        help="an ONNX steering model: behavioral cloning, DAgger (repeat for more)")
    parser.add_argument("--expert", action="store_true", help="the environment's expert too (the autopilot)")
    parser.add_argument("--worlds", type=int, default=20, help="unseen evaluation worlds (default %(default)s)")
    parser.add_argument("--world-seed", type=int, default=None, help="the first world's seed (default 1000000)")
    parser.add_argument("--world-config", default=None, metavar="JSON", help="generator settings (as rbc eval's)")
    parser.add_argument("--tracks", default=",".join(DEFAULT_TRACKS),
                        help="built-in tracks beside the worlds, comma-separated ('' for none; default %(default)s)")
    parser.add_argument("--workers", type=int, default=1, help="runs at once (default %(default)s)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        if args.workers < 1 or args.worlds < 0:
            raise BadValue("--workers must be >= 1 and --worlds >= 0")
        policies = parse_policies(args.ppo, args.onnx, args.expert)
        tracks = tuple(t.strip() for t in args.tracks.split(",") if t.strip())
        record = compare(policies, Path(args.out), args.worlds, args.world_seed, args.world_config, tracks,
                         args.workers)
    except Exception as exc:  # a user's mistake is one line; anything else a bug with its traceback
        from tools.errors import is_user_error

        if not is_user_error(exc):
            raise
        print(f"{parser.prog}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    print(table(record))
    print(f"{Path(args.out) / RECORD}")
    return 0


__all__ = ["PolicySpec", "compare", "score_policy", "table"]

if __name__ == "__main__":
    raise SystemExit(main())
