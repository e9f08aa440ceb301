"""``rbc monitor``: the misbehaviour monitor drive_server runs beside the steering model.

``fit`` trains a small autoencoder on nominal driving (SelfOracle's reconstruction error), sets its warning and
alarm thresholds from OTHER nominal runs as quantiles for a target false-alarm rate, and writes the steering
model's file with the monitor in its metadata (:mod:`models.monitoring`; served by :mod:`drive_server.serving.monitor`).
``failures`` drives the model on training worlds, perturbed, degraded and nominal, and keeps every frame's input
with the run's take-overs: what ``fit --score predictor`` learns from. ``eval`` measures it on the headless
simulator: held-out nominal driving, perturbed runs and degraded models,
the anchors' protocol and the deployment figures, ``act`` against ``warn``, and its cost
(:mod:`tools.monitoreval`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.errors import CommandError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from models.monitoring.fit import SCORES, FitPlan
    from tools.monitoreval.bench import EvalPlan

    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True,
                                help="fit: train and calibrate a monitor and attach it to a model file; eval: measure "
                                     "it on the headless simulator")
    fit = sub.add_parser("fit", formatter_class=parser.formatter_class, help="train, calibrate and attach a monitor",
                         description="train an autoencoder on the model's own input from nominal driving, set its "
                                     "thresholds on other nominal runs, write MODEL with the monitor as OUT")
    fit.add_argument("model", type=Path, help="the ONNX steering model (left as it is)")
    fit.add_argument("--out", type=Path, required=True, help="the model file with the monitor to write (.onnx)")
    fit.add_argument("--score", choices=SCORES, default=FitPlan.score,
                     help="autoencoder: SelfOracle's reconstruction error (trained on --data); shift: the model's "
                          "disagreement with itself on the frame moved 3 pixels sideways (no training); predictor: "
                          "how likely a failure is within 3 s, learnt from rbc monitor failures' runs (--data); "
                          "ensemble: the served steering's distance to the mean of other networks of the model's "
                          "recipe (--member, two or more) plus their spread; mcdropout: the same with the served "
                          "network itself under --samples fixed dropout masks as the other networks (a network "
                          "trained with dropout; no training); framestats: the frame's brightness and "
                          "contrast against nominal frames' (--data); keep: the "
                          "monitor MODEL already carries, its thresholds set afresh (default %(default)s)")
    fit.add_argument("--with-framestats", action="store_true",
                     help="also watch the frames' brightness and contrast against the nominal frames of --data "
                          "(a camera check beside the score: the larger of the two, each divided by its own alarm "
                          "threshold)")
    fit.add_argument("--data", type=Path, action="append", default=[], metavar="DIR",
                     help="nominal driving to train the autoencoder or fit the frame statistics on (Udacity-format "
                          "folder, e.g. from rbc collect), "
                          "or for the predictor a folder of rbc monitor failures (repeat)")
    fit.add_argument("--member", dest="members", type=Path, action="append", default=[], metavar="M.onnx",
                     help="for --score ensemble: a steering model trained to MODEL's recipe with another seed "
                          "(rbc train --recipe R --seed N), with exactly MODEL's preprocessing (repeat, two or more)")
    fit.add_argument("--samples", type=int, default=FitPlan.samples,
                     help="for --score mcdropout: dropout masks, each one more run of the network per frame "
                          "(default %(default)s)")
    fit.add_argument("--calibration", type=Path, action="append", required=True, metavar="DIR",
                     help="OTHER nominal driving to set the thresholds on, at least an hour for the default rates "
                          "(repeat; never evaluation worlds)")
    fit.add_argument("--epochs", type=int, default=FitPlan.epochs, help="training epochs (default %(default)s)")
    fit.add_argument("--stride", type=int, default=FitPlan.stride,
                     help="train on every N-th frame (default %(default)s)")
    fit.add_argument("--seed", type=int, default=FitPlan.seed, help="training seed (default %(default)s)")
    fit.add_argument("--warnings-per-hour", type=float, default=FitPlan.warnings_per_hour,
                     help="target warnings per hour of nominal driving (default %(default)s)")
    fit.add_argument("--alarms-per-hour", type=float, default=FitPlan.alarms_per_hour,
                     help="target alarms per hour of nominal driving (default %(default)s)")

    fl = sub.add_parser("failures", formatter_class=parser.formatter_class,
                        help="drive runs on training worlds and keep them for the failure predictor",
                        description="drive the model on training worlds (perturbed, degraded, nominal; never a "
                                    "benchmark, calibration or evaluation world) and write one file per run with "
                                    "every frame's input and the take-overs, for rbc monitor fit --score predictor "
                                    "(resumes from OUT)")
    fl.add_argument("model", type=Path, help="the ONNX steering model (carrying any monitor: its input is read "
                                             "through it)")
    fl.add_argument("--out", type=Path, required=True, help="folder for the run files")
    fl.add_argument("--set", dest="run_set", choices=("training", "calibration"), default="training",
                    help="training: the predictor's runs on worlds 30-199; calibration: the model's own nominal "
                         "driving on the calibration worlds 200-229, for fit --calibration (default %(default)s)")
    fl.add_argument("--per-setting", type=int, default=6,
                    help="runs per perturbation intensity and per degraded model (default %(default)s)")
    fl.add_argument("--nominal", type=int, default=20,
                    help="nominal runs (default %(default)s; with --set calibration 30 are about an hour)")
    fl.add_argument("--workers", type=int, default=1, help="processes driving runs side by side (default %(default)s)")

    ev = sub.add_parser("eval", formatter_class=parser.formatter_class, help="measure a monitor (a benchmark)",
                        description="drive held-out nominal runs, perturbed runs and degraded models with the monitor "
                                    "in warn and act; write OUT/monitor_eval.json and .md (resumes from OUT)")
    ev.add_argument("model", type=Path, help="an ONNX steering model carrying a monitor")
    ev.add_argument("--out", type=Path, required=True, help="folder for the journal, the record and the tables")
    ev.add_argument("--nominal", type=int, default=EvalPlan.nominal,
                    help="held-out nominal runs, one lap each (default %(default)s: about 3 simulated hours)")
    ev.add_argument("--per-setting", type=int, default=EvalPlan.per_setting,
                    help="runs per perturbation intensity and per degraded model (default %(default)s)")
    ev.add_argument("--no-act", dest="act", action="store_false", help="skip the closed-loop runs with act")
    ev.add_argument("--also", type=Path, action="append", default=[], metavar="M.onnx",
                    help="another monitor to compare on the very same drives: the same steering model with another "
                         "monitor attached (repeat)")
    ev.add_argument("--undertrained", type=Path, action="append", default=[], metavar="M.onnx",
                    help="a degraded model: a steering model of MODEL's recipe stopped early (rbc train --recipe R "
                         "--epochs 1, treated as MODEL was, e.g. rbc mirror), with MODEL's preprocessing and serving "
                         "settings; driven --per-setting times with MODEL's monitor attached (repeat)")
    ev.add_argument("--rescore", action="store_true",
                    help="drive nothing: score the runs OUT's journal holds again (after a change of the scoring "
                         "or the tables), whatever code drove them; the record lists those code versions")
    ev.add_argument("--workers", type=int, default=EvalPlan.workers,
                    help="processes driving runs side by side (default %(default)s)")
    ev.add_argument("--cost-log", type=Path, default=None, metavar="DIR",
                    help="recorded frames to time the server's pipeline on, monitor off and on (default: the "
                         "bundled test recording when present)")


def run(args: argparse.Namespace) -> int:
    if args.action == "eval":
        return _eval(args)
    if args.action == "failures":
        return _failures(args)
    return _fit(args)


def _failures(args: argparse.Namespace) -> int:
    import sys

    from tools.monitoreval.calibruns import calibration_runs
    from tools.monitoreval.failruns import collect_failures
    from tools.monitoreval.runset import failure_training_runs

    if not args.model.is_file():
        raise CommandError(f"no model at {args.model}")
    if args.per_setting < 0 or args.nominal < 0 or args.per_setting + args.nominal == 0 or args.workers < 1:
        raise CommandError("--per-setting and --nominal must be >= 0 (not both 0), --workers >= 1")
    import logging

    if not logging.getLogger().isEnabledFor(logging.DEBUG):
        logging.getLogger("drive_server.serving.client_monitor").setLevel(logging.ERROR)
    specs = calibration_runs(args.nominal) if args.run_set == "calibration" else \
        failure_training_runs(args.per_setting, args.nominal)

    def progress(done: int, total: int, what: str) -> None:
        print(f"run {done} of {total}: {what}", file=sys.stderr, flush=True)

    files = collect_failures(specs, args.model, args.out, args.workers, progress)
    print(f"wrote {len(files)} runs to {args.out}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    import sys

    from tools.console import Progress, interactive
    from tools.monitoreval.bench import TABLES, EvalPlan, evaluate

    if not args.model.is_file():
        raise CommandError(f"no model at {args.model}")
    if args.nominal < 1 or args.per_setting < 1:
        raise CommandError("--nominal and --per-setting must be >= 1")
    for path in args.undertrained:
        if not path.is_file():
            raise CommandError(f"--undertrained {path}: no such file")
    cost_log = args.cost_log
    if cost_log is None:
        sample = Path(__file__).resolve().parents[2] / "tests" / "data" / "udacity-sample"
        cost_log = sample if sample.is_dir() else None
    plan = EvalPlan(args.model, args.out, nominal=args.nominal, per_setting=args.per_setting, act=args.act,
                    cost_log=cost_log, workers=args.workers, shadows=tuple(args.also),
                    undertrained=tuple(args.undertrained), rescore=args.rescore)
    import logging

    if not logging.getLogger().isEnabledFor(logging.DEBUG):  # hundreds of runs: their state changes only with -v
        logging.getLogger("drive_server.serving.client_monitor").setLevel(logging.ERROR)
    bar = Progress("runs", "run")

    def progress(done: int, total: int, what: str) -> None:
        if interactive():
            bar(done, total)
        else:
            print(f"run {done} of {total}: {what}", file=sys.stderr, flush=True)

    try:
        evaluate(plan, progress=progress)
    finally:
        bar.close()
    print((args.out / TABLES).read_text(encoding="utf-8"))
    return 0


def _fit(args: argparse.Namespace) -> int:
    from models.monitoring.fit import FitPlan, fit_monitor

    if args.out.suffix != ".onnx":
        raise CommandError(f"--out {args.out}: give a path ending in .onnx")
    for folder in [args.model, *args.members, *args.data, *args.calibration]:
        if not folder.exists():
            raise CommandError(f"no such file or folder: {folder}")
    plan = FitPlan(args.model, args.out, tuple(args.data), tuple(args.calibration), score=args.score,
                   members=tuple(args.members), samples=args.samples, with_framestats=args.with_framestats,
                   epochs=args.epochs, stride=args.stride, seed=args.seed, warnings_per_hour=args.warnings_per_hour,
                   alarms_per_hour=args.alarms_per_hour)
    result = fit_monitor(plan, say=print)
    spec, cal = result.spec, result.info
    short = f" (calibration too short for the {' and '.join(cal['short'])} rate: its maximum is used)" \
        if cal["short"] else ""
    print(f"wrote {args.out}: monitor {spec.score}, warning at {spec.warn:.4g}, alarm at {spec.alarm:.4g} "
          f"(one-second mean; nominal median {cal['nominal_p50']:.4g}, max {cal['nominal_max']:.4g} over "
          f"{cal['hours']:.2f} h){short}")
    return 0
