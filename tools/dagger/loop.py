"""The rounds of ``rbc dagger``: collect, aggregate, retrain from scratch, export, score; resumable.

Round r (``OUT/round-RR/``):

1. ``data/``: ``config.new_frames(r)`` frames driven on training worlds, every one labelled by the expert
   (:mod:`tools.dagger.rollout`). Round 0 is the expert's alone (behavioral cloning on its laps); from round 1 the
   previous round's model drives each step with probability 1 - beta, beta = beta0 * beta_decay ** r. The "bc"
   baseline is the same loop with the expert driving every step of every round, so both see the same worlds,
   spawns and recipe and differ only in who drove while the frames were labelled.
2. ``train/``: ``rbc train``'s pipeline (the recipe, its augmentations, ONNX export) on the aggregate, the data of
   rounds 0..r, from scratch with the same seed (the standard algorithm; retraining from scratch keeps every round's
   model a function of its data alone).
3. ``eval/``: the model scored as ``rbc eval`` scores it (:mod:`tools.dagger.scoring`).
4. ``record.json``: the round's figures, its seed, the run's config and the code version, written last and
   atomically: a round with a record is finished and never redone.

A run is keyed (``dagger.json``) on its config, its recipe file's content and the code of every step
(:data:`RUN_ENTRY` and all it imports: collection, training, scoring); a resume under another key is refused, so
no run mixes rounds of two versions.

A killed run continues with ``resume=True`` at its first unfinished round, inside it at the first unfinished step
(a half-collected ``data.partial`` is collected again, an interrupted training continues from its checkpoint,
finished evaluation runs are reused from the journal), and gives the clean run's records.
"""

from __future__ import annotations

import logging
import shutil
import time
from collections.abc import Callable, Mapping
from pathlib import Path

from models.networks.runfiles import EpochRow, RunPaths, RunRecord
from protocol.codeversion import ROOT, code_digest
from protocol.errors import BadValue
from protocol.runrecords import code_version, file_sha256, read_json, write_json
from tools.dagger.config import DaggerConfig
from tools.dagger.records import RoundRecord, RoundScores, TrainingSummary
from tools.dagger.rollout import SUMMARY, CollectionStats, collect_round, read_stats
from tools.dagger.summary import write_summary
from tools.sim.driving.rules import TARGET_ETA

log = logging.getLogger(__name__)

RUN_FILE = "dagger.json"
RECORD = "record.json"
WORLDS_DIR = "worlds"
#: Where a round starts (its code is this module and all it imports), and the tree that code is read from.
RUN_ENTRY = __name__
CODE_ROOT = ROOT


class Stopped(Exception):
    """The run was interrupted (Ctrl-C during training); what is finished is kept, ``--resume`` continues."""


def round_dir(out: Path, round_: int) -> Path:
    return out / f"round-{round_:02d}"


def run_key(config: DaggerConfig) -> dict[str, str]:
    """What a run's rounds depend on beyond its config: the recipe file's content and the code of every step."""
    from models.training.recipe import find_recipe

    return {"recipe_sha256": file_sha256(find_recipe(config.recipe)), "code": code_digest(RUN_ENTRY, root=CODE_ROOT)}


def prepare_run(config: DaggerConfig, out: Path, resume: bool) -> dict[str, object]:
    """Check or start ``OUT/dagger.json``; a resume must find the same settings (more budgets may follow), the same
    recipe and the same code (:func:`run_key`)."""
    run_file = out / RUN_FILE
    key = run_key(config)
    if run_file.is_file():
        if not resume:
            raise BadValue(f"{out} holds a DAgger run already", "add --resume to continue it, or use a new --out")
        earlier = read_json(run_file)
        stored = DaggerConfig.from_dict(earlier["config"])
        if not stored.same_run(config):
            mine, theirs = stored.to_dict(), config.to_dict()
            diff = sorted(k for k in mine if mine[k] != theirs[k])
            raise BadValue(f"--resume: {out} was started with other settings ({', '.join(diff)})",
                           "give the same flags as the first run (more --rounds may follow), or a new --out")
        if earlier.get("key") != key:
            what = [k for k in key if (earlier.get("key") or {}).get(k) != key[k]]
            raise BadValue(f"--resume: {out} was started with another {' and '.join(what)} (its rounds would mix two "
                           "versions)", "start afresh in a new --out")
    elif out.is_dir() and any(out.iterdir()):
        raise BadValue(f"{out} is not empty and holds no DAgger run", "give a new or empty --out")
    out.mkdir(parents=True, exist_ok=True)
    meta = {"config": config.to_dict(), "seed": config.seed, "key": key, "code_version": code_version()}
    write_json(run_file, meta)
    return meta


def eval_worlds(config: DaggerConfig, out: Path) -> list[tuple[int, str]]:
    """The unseen evaluation worlds, generated once into ``OUT/worlds`` (the same files every round)."""
    from tools.evaluate.worlds import write_eval_worlds

    if not config.eval_worlds:
        return []
    meta = write_eval_worlds(out, config.eval_seeds(), config.world_gen_config(), resume=True)
    return [(int(seed), path) for seed, path in meta["files"].items()]


def run(config: DaggerConfig, out: Path, resume: bool = False, workers: int = 1, threads: int | None = None,
        progress: bool = True, on_round: Callable[[RoundRecord], None] | None = None) -> list[RoundRecord]:
    """Every round of ``config`` in ``out``; the rounds' records (finished ones read back, not redone)."""
    out = Path(out)
    prepare_run(config, out, resume)
    worlds = eval_worlds(config, out)
    records: list[RoundRecord] = []
    for r in range(config.rounds):
        path = round_dir(out, r) / RECORD
        record: RoundRecord
        if path.is_file():
            record = read_json(path)
            log.info("round %d/%d: finished earlier (%d expert frames, worst world %.1f %%)", r + 1, config.rounds,
                     record["expert_frames"], record["eval"]["all"]["worst"])
        else:
            record = run_round(config, out, r, worlds, workers=workers, threads=threads, progress=progress)
        records.append(record)
        write_summary(out, config, records)
        if on_round is not None:
            on_round(record)
    return records


def run_round(config: DaggerConfig, out: Path, r: int, worlds: list[tuple[int, str]], workers: int = 1,
              threads: int | None = None, progress: bool = True) -> RoundRecord:
    """Collect, train and score round ``r``; write and return its record."""
    from tools.console import Progress, RunProgress
    from tools.dagger.scoring import evaluate_model, runs_planned

    folder = round_dir(out, r)
    folder.mkdir(parents=True, exist_ok=True)
    beta = config.beta(r)
    learner = None if r == 0 or beta >= 1.0 else model_path(out, r - 1)
    timing: dict[str, float] = {}

    data = folder / "data"
    started = time.perf_counter()
    if (data / SUMMARY).is_file():
        stats = read_stats(data)
    else:
        bar = Progress(f"round {r} frames", unit="frame") if progress else None
        try:
            stats = collect_round(config, r, data, learner, progress=bar)
        finally:
            if bar is not None:
                bar.close()
    timing["collect_s"] = round(time.perf_counter() - started, 1)
    log.info("round %d/%d (beta %.3g): %d frames (%d driven by the learner, %d take-overs while collecting) in %.0f s",
             r + 1, config.rounds, beta, stats.frames, stats.learner_steps, stats.takeovers, timing["collect_s"])

    started = time.perf_counter()
    training = train_round(config, out, r, threads=threads, progress=progress)
    timing["train_s"] = round(time.perf_counter() - started, 1)
    model = model_path(out, r)
    log.info("round %d/%d: trained on %d frames in %.0f s (val MSE %.5f)", r + 1, config.rounds,
             config.budgets[r], timing["train_s"], training["val_loss"])

    started = time.perf_counter()
    runs = RunProgress(runs_planned(config)) if progress else None
    try:
        scores = evaluate_model(model, folder / "eval", config, worlds, workers=workers,
                                on_result=runs.record if runs else None)
    finally:
        if runs is not None:
            runs.close()
    timing["eval_s"] = round(time.perf_counter() - started, 1)
    record = make_record(config, r, stats, learner, training, model, scores)
    record["timing"] = timing  # the only part a resumed run may give differently
    write_json(folder / RECORD, record)
    log.info("round %d/%d: %d expert frames: %s", r + 1, config.rounds, config.budgets[r], headline(record))
    return record


def model_path(out: Path, round_: int) -> Path:
    return RunPaths(train_dir(out, round_)).model


def train_dir(out: Path, round_: int) -> Path:
    """Round ``round_``'s training run (an ``rbc train`` run folder)."""
    return round_dir(out, round_) / "train"


def train_round(config: DaggerConfig, out: Path, r: int, threads: int | None = None,
                progress: bool = True) -> TrainingSummary:
    """Train round ``r``'s model on the data of rounds 0..r (``rbc train``'s pipeline); continue an interrupted
    training from its checkpoint. What the record keeps of it."""
    from models.training.recipe import load_recipe
    from models.training.train import TrainConfig, train

    run_dir = train_dir(out, r)
    paths = RunPaths(run_dir)
    if not paths.model.is_file():
        if paths.checkpoint.is_file():
            result = train(TrainConfig(data=[], out=str(run_dir), threads=threads, progress=progress), resume=True)
        else:
            shutil.rmtree(run_dir, ignore_errors=True)  # begun but nothing saved: start again, the same
            overrides = {k: v for k, v in (("epochs", config.epochs),
                                           ("max_steps_per_epoch", config.max_steps_per_epoch)) if v is not None}
            train_config = load_recipe(config.recipe, **overrides, seed=config.seed, out=str(run_dir),
                                       data=[str(round_dir(out, k) / "data") for k in range(r + 1)],
                                       threads=threads, progress=progress)
            result = train(train_config)
        if result.interrupted:
            raise Stopped(f"training of round {r} interrupted; its checkpoint is in {run_dir}")
    run = RunRecord.load(run_dir)
    last = run.last_epoch or EpochRow(0, float("nan"), float("nan"), 0.0)
    stored = run.config  # paths relative to OUT: a record says the same wherever the run lies
    stored["data"] = [_relative(d, out) for d in stored.get("data", [])]
    stored["out"] = _relative(stored.get("out", str(run_dir)), out)
    return {"recipe": config.recipe, "config": stored, "resolved": run.resolved,
            "val_loss": last.val_loss, "train_loss": last.train_loss,
            "epochs": len(run.history)}


def _relative(path: str, out: Path) -> str:
    try:
        return Path(path).resolve().relative_to(out.resolve()).as_posix()
    except ValueError:
        return path


def make_record(config: DaggerConfig, r: int, stats: CollectionStats, learner: Path | None,
                training: TrainingSummary, model: Path, scores: RoundScores) -> RoundRecord:
    worlds = scores.get("worlds")
    return {
        "round": r, "mode": config.mode, "beta": config.beta(r),
        "frames_new": stats.frames, "expert_frames": config.budgets[r],
        "collection": stats.as_record(),
        "learner_sha256": file_sha256(learner) if learner else None,
        "training": training, "model": model.relative_to(model.parents[2]).as_posix(),
        "model_sha256": file_sha256(model),
        "eval": scores,
        "target": {"eta": TARGET_ETA, "every_world": bool(worlds and worlds["at_target"] == worlds["n"]),
                   "worlds_at_target": worlds["at_target"] if worlds else 0},
        "seed": config.seed, "config": config.to_dict(), "code_version": code_version(),
    }


def headline(record: RoundRecord) -> str:
    """``worlds 91.2 % mean, worst 80.1 % (world 1000004), 17/20 at >= 95 %; lake 100.0 %, mountain 96.5 %``."""
    ev = record["eval"]
    parts = []
    if "worlds" in ev:
        w = ev["worlds"]
        parts.append(f"worlds {w['mean']:.1f} % mean, worst {w['worst']['eta']:.1f} % (world {w['worst']['seed']}), "
                     f"{w['at_target']}/{w['n']} at >= {TARGET_ETA:.0f} %, {w['takeovers']} take-overs")
    parts += [f"{name} {t['eta']:.1f} %" for name, t in ev["tracks"].items()]
    return "; ".join(parts)


def comparable(record: Mapping[str, object]) -> dict[str, object]:
    """A record without what may differ between a clean and a resumed run (wall times)."""
    return {k: v for k, v in record.items() if k != "timing"}
