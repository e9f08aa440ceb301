"""``rbc compare``: the paper's Table 10, side by side for several evaluated models.

Each column is an ``rbc eval`` output folder (robustness), optionally the ``rbc train`` run folder of
the same model (training time); deployment latency is measured here, with the drive server's own
per-stage statistics, on the same frames for every model.
"""

from __future__ import annotations

import argparse
import json
import logging
import tempfile
from pathlib import Path
from typing import Any

from models.runfiles import CONFIG, HISTORY, read_history, write_text
from tools.evaluate.experiments import AUTONOMY_RULE, EXPERIMENTS, experiment
from tools.evaluate.report import format_cell, format_range

log = logging.getLogger("rbc.compare")

#: Table 10 rows (the paper leaves out the obstacle experiment there).
TABLE10_EXPERIMENTS = tuple(e for e in EXPERIMENTS if e.key != "obstacles")
#: The paper's Table 10 ranges (offsets from the default), as numbers: the table and the chart use them.
PAPER_TABLE10_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "NVIDIA's approach (paper)": {"light_intensity": (-0.2, 0.3), "light_direction": (-3.0, 7.0),
                                  "orientation": (-20.0, 10.0)},
    "Our approach (paper)": {"light_intensity": (-0.6, 1.2), "light_direction": (-30.0, 30.0),
                             "orientation": (-45.0, 10.0)},
}
PAPER_TABLE10 = {
    "NVIDIA's approach (paper)": {
        "training_time": "~1.8 hr", "latency": "4-7 ms (mode 4.99 ms)", "no_variation": "≈100 %",
        "position": "≈100 %", "heading_inversion": "≈100 %", "speed_limit": "50 km/h"},
    "Our approach (paper)": {
        "training_time": "~1.4 hr", "latency": "2-6 ms (mode 3.99 ms)", "no_variation": "≈100 %",
        "position": "≈100 %", "heading_inversion": "≈100 %", "speed_limit": "100 km/h"},
}
for _column, _ranges in PAPER_TABLE10_RANGES.items():
    PAPER_TABLE10[_column].update({k: format_range(lo, hi, experiment(k).unit) for k, (lo, hi) in _ranges.items()})


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--eval", dest="evals", type=Path, action="append", required=True, metavar="DIR",
                   help="an rbc eval output folder (repeat: one per column)")
    p.add_argument("--label", dest="labels", action="append", default=None, metavar="TEXT",
                   help="column title (repeat, same order as --eval)")
    p.add_argument("--train-run", dest="runs", type=Path, action="append", default=None, metavar="DIR",
                   help="rbc train run folder of the same model, for the training time (same order)")
    p.add_argument("--frames", type=int, default=2000, help="frames per latency measurement")
    p.add_argument("--no-paper", action="store_true", help="leave out the paper's columns")
    p.add_argument("--layout", choices=("table10", "table9"), default="table10",
                   help="table10: models side by side with training time and latency; table9: one eval "
                        "per behavior (simplistic, rigorous, collision) in the layout of the paper's Table 9")
    p.add_argument("--out", type=Path, required=True, help="Markdown file to write (and .json beside it)")


def training_summary(run_dir: Path | None) -> dict[str, Any]:
    """Budget (config.json), wall seconds and final validation MSE (history.csv) of a training run.

    The budget makes unequal schedules visible in the table; an empty dict when nothing is known.
    """
    if run_dir is None:
        return {}
    out: dict[str, Any] = {}
    if (run_dir / CONFIG).is_file():
        stored = json.loads((run_dir / CONFIG).read_text(encoding="utf-8"))
        cfg, resolved = stored.get("config", {}), stored.get("resolved", {})
        out.update(arch=cfg.get("arch"), approach=cfg.get("approach"), epochs=resolved.get("epochs"),
                   steps_per_epoch=resolved.get("steps_per_epoch"), batch_size=cfg.get("batch_size"),
                   aug_loops=cfg.get("aug_loops"))
    if not (run_dir / HISTORY).is_file():
        log.warning("no %s in %s: training time unknown", HISTORY, run_dir)
        return out
    rows = read_history(run_dir / HISTORY)
    if rows:
        out.update(seconds=sum(r["seconds"] for r in rows), val_mse=rows[-1]["val_loss"])
    return out


def training_time_s(run_dir: Path | None) -> float | None:
    """Wall seconds of a training run: the sum of history.csv's per-epoch seconds."""
    return training_summary(run_dir).get("seconds")


def _fmt_budget(train: dict[str, Any]) -> str:
    if not train.get("epochs") or not train.get("steps_per_epoch") or not train.get("batch_size"):
        return "n/a"
    samples = train["epochs"] * train["steps_per_epoch"] * train["batch_size"]
    steps = f"{train['epochs']} × {train['steps_per_epoch']} steps of {train['batch_size']}"
    return f"{steps} ({samples / 1e6:.2f} M samples)"


def measure_latency(model: Path, frames: int) -> dict[str, Any]:
    """Serve ``model`` with drive_server and drive it with the Unity-wire client; server stats + round trip."""
    import numpy as np

    from tools.bench import drive
    from tools.server_process import ServerProcess

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


def _fmt_latency(lat: dict[str, Any]) -> str:
    total = lat.get("server_total_ms") or {}
    rt = lat["round_trip_ms"]
    server = f"server {total['p50']:.2f} ms (p99 {total['p99']:.2f}, max {total['max']:.1f})" if total else ""
    return f"{server}; round trip {rt['p50']:.2f} ms (p99 {rt['p99']:.2f})".lstrip("; ")


def build_table(columns: list[dict[str, Any]], with_paper: bool = True) -> str:
    head = ["Parameter"] + [c["label"] for c in columns]
    paper = list(PAPER_TABLE10.items()) if with_paper else []
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
    for exp in TABLE10_EXPERIMENTS:
        row(exp.title, [format_cell(c["summary"].get(exp.key)) for c in columns], exp.key)
    lines += ["", f"~100 % means: {AUTONOMY_RULE}. Latency: drive_server's own decode-to-command time "
              "and the Unity-wire round trip on this machine (the paper: preprocessing to command on an RTX 2070)."]
    return "\n".join(lines) + "\n"


def _table9(args: argparse.Namespace) -> int:
    from tools.evaluate.report import table9

    summaries = {}
    for eval_dir in args.evals:
        results = json.loads((eval_dir / "results.json").read_text(encoding="utf-8"))
        summaries[results["meta"]["behavior"]] = results["summary"]
    table = table9(summaries, with_paper=not args.no_paper)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, table)
    print(table)
    print(f"wrote {args.out}")
    return 0


def run(args: argparse.Namespace) -> int:
    missing = [d for d in args.evals if not (d / "results.json").is_file()]
    if missing:
        log.error("%s has no results.json: run rbc eval --out %s first", missing[0], missing[0])
        return 2
    if args.layout == "table9":
        return _table9(args)
    labels = args.labels or [d.name for d in args.evals]
    runs = args.runs or [None] * len(args.evals)
    if len(labels) != len(args.evals) or len(runs) != len(args.evals):
        log.error("give as many --label and --train-run as --eval (or none)")
        return 2
    columns = []
    for label, eval_dir, run_dir in zip(labels, args.evals, runs, strict=True):
        results = json.loads((eval_dir / "results.json").read_text(encoding="utf-8"))
        model = Path(results["meta"]["model"])
        log.info("measuring the deployment latency of %s", model)
        training = training_summary(run_dir)
        columns.append({"label": label, "eval_dir": str(eval_dir), "model": str(model),
                        "model_sha256": results["meta"]["model_sha256"], "summary": results["summary"],
                        "training_time_s": training.get("seconds"), "training": training,
                        "latency": measure_latency(model, args.frames)})
    table = build_table(columns, with_paper=not args.no_paper)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, table)
    write_text(args.out.with_suffix(".json"), json.dumps(columns, indent=2, default=str))
    from tools.evaluate.range_chart import plot_ranges

    chart = plot_ranges(columns, args.out.with_suffix(".png"), with_paper=not args.no_paper)
    print(table)
    print(f"wrote {args.out}" + (f" and {chart}" if chart else ""))
    return 0
