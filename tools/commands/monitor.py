"""``rbc monitor``: the misbehaviour monitor drive_server runs beside the steering model.

``fit`` trains a small autoencoder on nominal driving (SelfOracle's reconstruction error), sets its warning and
alarm thresholds from OTHER nominal runs as quantiles for a target false-alarm rate, and writes the steering
model's file with the monitor in its metadata (:mod:`models.monitoring`; served by :mod:`drive_server.monitor`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.errors import CommandError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from models.monitoring.fit import FitPlan

    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True,
                                help="fit: train and calibrate a monitor and attach it to a model file")
    fit = sub.add_parser("fit", formatter_class=parser.formatter_class, help="train, calibrate and attach a monitor",
                         description="train an autoencoder on the model's own input from nominal driving, set its "
                                     "thresholds on other nominal runs, write MODEL with the monitor as OUT")
    fit.add_argument("model", type=Path, help="the ONNX steering model (left as it is)")
    fit.add_argument("--out", type=Path, required=True, help="the model file with the monitor to write (.onnx)")
    fit.add_argument("--data", type=Path, action="append", required=True, metavar="DIR",
                     help="nominal driving to train on (Udacity-format folder, e.g. from rbc collect; repeat)")
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


def run(args: argparse.Namespace) -> int:
    from models.monitoring.fit import FitPlan, fit_monitor

    if args.out.suffix != ".onnx":
        raise CommandError(f"--out {args.out}: give a path ending in .onnx")
    for folder in [args.model, *args.data, *args.calibration]:
        if not folder.exists():
            raise CommandError(f"no such file or folder: {folder}")
    plan = FitPlan(args.model, args.out, tuple(args.data), tuple(args.calibration), epochs=args.epochs,
                   stride=args.stride, seed=args.seed, warnings_per_hour=args.warnings_per_hour,
                   alarms_per_hour=args.alarms_per_hour)
    result = fit_monitor(plan, say=print)
    spec, cal = result.spec, result.info
    short = f" (calibration too short for the {' and '.join(cal['short'])} rate: its maximum is used)" \
        if cal["short"] else ""
    print(f"wrote {args.out}: monitor {spec.score}, warning at {spec.warn:.4g}, alarm at {spec.alarm:.4g} "
          f"(one-second mean; nominal median {cal['nominal_p50']:.4g}, max {cal['nominal_max']:.4g} over "
          f"{cal['hours']:.2f} h){short}")
    return 0
