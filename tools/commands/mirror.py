"""``rbc mirror``: an existing ONNX model mirror-averaged, (f(x) - f(mirror x)) / 2, for models whose training run
is gone (:mod:`models.onnxfiles.mirror_onnx`); a recipe's ``[export] mirror_average`` does the same at
export."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.errors import CommandError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", type=Path,
                   help="the ONNX steering model to mirror-average (left as it is; not a lane-keeping, rigorous "
                        "model: the average drives the road's middle)")
    p.add_argument("--out", type=Path, required=True, help="the mirror-averaged model to write (.onnx)")
    p.add_argument("--serve-smooth", "--smoothing", dest="smoothing", type=float, default=None, metavar="ALPHA",
                   help="ask drive_server to smooth each client's steering with this weight of the new output, "
                        "as a recipe's [export] smoothing (1: off; default: what the model asks for)")
    p.add_argument("--gain", "--output-scale", dest="gain", type=float, default=None, metavar="G",
                   help="ask drive_server to multiply the steering by G (0.1..2), as a recipe's [export] gain "
                        "(default: what the model asks for)")


def run(args: argparse.Namespace) -> int:
    from drive_server.serving.model import SteeringModel
    from models.onnxfiles.mirror_onnx import MirrorError, mirror_average_onnx

    if args.out.suffix != ".onnx":
        raise CommandError(f"--out {args.out}: give a path ending in .onnx")
    if args.out.resolve() == args.model.resolve():
        raise CommandError("--out must not be the model itself (it is read to verify the result)")
    if not args.model.is_file():
        raise CommandError(f"no model at {args.model}")
    try:
        worst = mirror_average_onnx(args.model, args.out, args.smoothing, gain=args.gain)
        serving = SteeringModel(args.out).serving
    except (MirrorError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    print(f"wrote {args.out}: (f(x) - f(mirror x)) / 2 of {args.model.name}, max |difference| {worst:.1e} "
          f"on random inputs" + (f"; drive_server serves it {serving.describe()}" if serving.asks_anything else ""))
    return 0
