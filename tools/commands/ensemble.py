"""``rbc ensemble``: several ONNX steering models averaged into one file, e.g. the same recipe trained from
different seeds; drive_server serves it like any model (:mod:`models.onnxfiles.ensemble_onnx`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.errors import CommandError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("models", type=Path, nargs="+", metavar="MODEL",
                   help="the ONNX steering models to average (two or more, read through the same preprocessing)")
    p.add_argument("--out", type=Path, required=True, help="the ensemble to write (.onnx)")
    p.add_argument("--serve-smooth", type=float, default=None, metavar="ALPHA",
                   help="ask drive_server to smooth each client's steering with this weight of the new output, "
                        "as a recipe's [export] smoothing (1: off; default: what the members ask, which must "
                        "agree)")


def run(args: argparse.Namespace) -> int:
    from drive_server.serving.smoothing import check_alpha
    from models.onnxfiles.ensemble_onnx import EnsembleError, ensemble_onnx

    if args.out.suffix != ".onnx":
        raise CommandError(f"--out {args.out}: give a path ending in .onnx")
    for model in args.models:
        if not model.is_file():
            raise CommandError(f"no model at {model}")
        if model.resolve() == args.out.resolve():
            raise CommandError("--out must not be one of the models (they are read to verify the result)")
    try:
        alpha = None if args.serve_smooth is None else check_alpha(args.serve_smooth)
        worst = ensemble_onnx(args.models, args.out, alpha)
    except (EnsembleError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    print(f"wrote {args.out}: the mean of {len(args.models)} models, max |difference| {worst:.1e} on random inputs")
    return 0
