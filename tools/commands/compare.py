"""``rbc compare``: the paper's Table 10 (or Table 9) side by side for several evaluated models."""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

from protocol.runrecords import write_text
from tools.errors import CommandError
from tools.evaluate.compare import Column, build_table, evaluated_model, measure_latency, training_summary
from tools.evaluate.evalrecord import EvalRecord

log = logging.getLogger("rbc.compare")


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


def _table9(args: argparse.Namespace) -> int:
    from tools.evaluate.report import table9

    summaries = {}
    for eval_dir in args.evals:
        results = EvalRecord.load(eval_dir)
        summaries[results.behavior] = dict(results.summary)
    table = table9(summaries, with_paper=not args.no_paper)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, table)
    print(table)
    print(f"wrote {args.out}")
    return 0


def run(args: argparse.Namespace) -> int:
    for eval_dir in args.evals:  # every folder checked before any latency is measured
        EvalRecord.load(eval_dir)
    if args.layout == "table9":
        return _table9(args)
    labels = args.labels or [d.name for d in args.evals]
    runs = args.runs or [None] * len(args.evals)
    if len(labels) != len(args.evals) or len(runs) != len(args.evals):
        raise CommandError("give as many --label and --train-run as --eval (or none)")
    columns: list[Column] = []
    for label, eval_dir, run_dir in zip(labels, args.evals, runs, strict=True):
        results = EvalRecord.load(eval_dir)
        model = evaluated_model(results)
        log.info("measuring the deployment latency of %s", model)
        training = training_summary(run_dir)
        columns.append({"label": label, "eval_dir": str(eval_dir), "model": str(model),
                        "model_sha256": results.model_sha256, "summary": dict(results.summary),
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
