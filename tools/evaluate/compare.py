"""``rbc compare``: the paper's Table 10, side by side for several evaluated models.

Each column is an ``rbc eval`` output folder (robustness), optionally the ``rbc train`` run folder of
the same model (training time); deployment latency is measured here, with the drive server's own
per-stage statistics, on the same frames for every model.
"""

from __future__ import annotations

import json
import logging
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypedDict

from models.networks.runfiles import HISTORY, RunPaths, RunRecord, read_history
from protocol.runrecords import file_sha256
from tools.errors import CommandError
from tools.evaluate.evalrecord import EvalRecord
from tools.evaluate.experiments import AUTONOMY_RULE, EXPERIMENTS, experiment
from tools.evaluate.paper import PAPER_TABLE10, PAPER_TABLE10_RANGES
from tools.evaluate.report import format_cell, format_range, shown_experiments

log = logging.getLogger("rbc.compare")

#: Table 10 rows (the paper leaves out the obstacle experiment there).
TABLE10_EXPERIMENTS = tuple(e for e in EXPERIMENTS if e.paper and e.key != "obstacles")


def evaluated_model(results: EvalRecord) -> Path:
    """The model file an evaluation drove: the path as given to rbc eval, else its absolute form (so a
    compare run from another folder finds it); one line when it has moved or changed since."""
    given, eval_dir = results.model, results.eval_dir
    found = next((p for p in (given, results.model_resolved) if p.is_file()), None)
    if found is None:
        raise CommandError(f"{eval_dir}: its model {given} is not found (moved, or a path relative to another "
                           "folder)", "run rbc compare from the folder rbc eval ran in, or evaluate it again")
    if file_sha256(found) != results.model_sha256:
        raise CommandError(f"{eval_dir}: {found} has changed since it was evaluated (sha256 differs)",
                           "evaluate the model again")
    return found


def paper_table10() -> dict[str, dict[str, str]]:
    """The paper's Table 10 columns as printed: the text cells, with the ranges formatted like ours."""
    return {column: cells | {k: format_range(lo, hi, experiment(k).unit) for k, (lo, hi) in
                             PAPER_TABLE10_RANGES[column].items()} for column, cells in PAPER_TABLE10.items()}


class TrainingBudget(TypedDict, total=False):
    """What a column says of its model's training (nothing where the run is not given)."""

    arch: str | None
    approach: str | None
    epochs: int | None
    steps_per_epoch: int | None
    batch_size: int | None
    aug_loops: int | None
    seconds: float  # the wall seconds of its epochs
    val_mse: float  # the last epoch's


class LatencySummary(TypedDict):
    """drive_server's decode-to-command time (its stats' ``total`` stage: p50, p99, max ...; {} where the server
    wrote none) and the Unity-wire round trip (p50, p99, max), in ms."""

    server_total_ms: dict[str, float]
    round_trip_ms: dict[str, float]


class Column(TypedDict):
    """One evaluated model of the comparison (``rbc compare``'s JSON holds the list)."""

    label: str
    eval_dir: str
    model: str
    model_sha256: str
    summary: dict[str, Any]  # the evaluation's summary (results.json), by experiment
    training_time_s: float | None
    training: TrainingBudget
    latency: LatencySummary


def training_summary(run_dir: Path | None) -> TrainingBudget:
    """Budget (config.json), wall seconds and final validation MSE (history.csv) of a training run.

    The budget makes unequal schedules visible in the table; an empty dict when nothing is known.
    """
    if run_dir is None:
        return {}
    out: TrainingBudget = {}
    paths = RunPaths(run_dir)
    if paths.config.is_file():
        run = RunRecord.load(run_dir)
        cfg, resolved = run.config, run.resolved
        out.update({"arch": cfg.get("arch"), "approach": cfg.get("approach"), "epochs": resolved.get("epochs"),
                    "steps_per_epoch": resolved.get("steps_per_epoch"), "batch_size": cfg.get("batch_size"),
                    "aug_loops": cfg.get("aug_loops")})
    if not paths.history.is_file():
        log.warning("no %s in %s: training time unknown", HISTORY, run_dir)
        return out
    rows = read_history(paths.history)
    if rows:
        out.update({"seconds": sum(r.seconds for r in rows), "val_mse": rows[-1].val_loss})
    return out


def training_time_s(run_dir: Path | None) -> float | None:
    """Wall seconds of a training run: the sum of history.csv's per-epoch seconds."""
    return training_summary(run_dir).get("seconds")


def _fmt_budget(train: TrainingBudget) -> str:
    epochs, steps_per_epoch, batch_size = train.get("epochs"), train.get("steps_per_epoch"), train.get("batch_size")
    if not epochs or not steps_per_epoch or not batch_size:
        return "n/a"
    samples = epochs * steps_per_epoch * batch_size
    steps = f"{epochs} × {steps_per_epoch} steps of {batch_size}"
    return f"{steps} ({samples / 1e6:.2f} M samples)"


def measure_latency(model: Path, frames: int) -> LatencySummary:
    """Serve ``model`` with drive_server and drive it with the Unity-wire client; server stats + round trip."""
    import numpy as np

    from tools.bench.latency import drive
    from tools.wire.server_process import ServerProcess

    with tempfile.TemporaryDirectory(prefix="rbc_compare_") as tmp:
        stats_path = Path(tmp) / "stats.json"
        with ServerProcess(model, ["--log-every", "0"], stats_json=stats_path) as server:
            rtts, _ = drive(server.url, None, 1, frames, 100)
        stats = json.loads(stats_path.read_text(encoding="utf-8")) if stats_path.is_file() else {}
    total = stats.get("total", {}).get("stages_ms", {}).get("total", {})
    p50, p99 = (float(v) for v in np.percentile(rtts, [50, 99]) * 1e3)
    return {"server_total_ms": total, "round_trip_ms": {"p50": p50, "p99": p99, "max": float(rtts.max() * 1e3)}}


def _fmt_time(seconds: float | None) -> str:
    if seconds is None:
        return "n/a"
    return f"{seconds / 60:.1f} min" if seconds < 3600 else f"{seconds / 3600:.2f} hr"


def _fmt_latency(lat: LatencySummary) -> str:
    total = lat.get("server_total_ms") or {}
    rt = lat["round_trip_ms"]
    server = f"server {total['p50']:.2f} ms (p99 {total['p99']:.2f}, max {total['max']:.1f})" if total else ""
    return f"{server}; round trip {rt['p50']:.2f} ms (p99 {rt['p99']:.2f})".lstrip("; ")


def build_table(columns: Sequence[Column], with_paper: bool = True) -> str:
    head = ["Parameter"] + [c["label"] for c in columns]
    paper = list(paper_table10().items()) if with_paper else []
    head += [name for name, _ in paper]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def row(title: str, cells: list[str], key: str) -> None:
        lines.append("| " + " | ".join([title, *cells, *(p.get(key, "–") for _, p in paper)]) + " |")

    row("Training time", [_fmt_time(c["training_time_s"]) for c in columns], "training_time")
    if any(c.get("training") for c in columns):
        row("Training budget", [_fmt_budget(c.get("training") or {}) for c in columns], "training_budget")
        row("Validation MSE", [f"{c['training']['val_mse']:.4f}" if "val_mse" in (c.get("training") or {})
                               else "n/a" for c in columns], "val_mse")
    row("Deployment latency", [_fmt_latency(c["latency"]) for c in columns], "latency")
    beyond = [e for e in shown_experiments(c["summary"] for c in columns) if not e.paper]
    for exp in (*TABLE10_EXPERIMENTS, *beyond):
        row(exp.title, [format_cell(c["summary"].get(exp.key)) for c in columns], exp.key)
    lines += ["", f"~100 % means: {AUTONOMY_RULE}. Latency: drive_server's own decode-to-command time "
              "and the Unity-wire round trip on this machine (the paper: preprocessing to command on an RTX 2070)."]
    return "\n".join(lines) + "\n"
