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
    p.add_argument("--serve-smooth", type=float, default=1.0, metavar="ALPHA",
                   help="also ask drive_server to smooth each client's steering with this weight of the new output, "
                        "as a recipe's [export] smoothing (default %(default)s: off)")
    p.add_argument("--output-scale", type=float, default=1.0, metavar="S",
                   help="the mirrored model answers S times the average, as a recipe's [export] output_scale (0.1..2; "
                        "default %(default)s)")


def run(args: argparse.Namespace) -> int:
    from drive_server.smoothing import check_alpha
    from models.onnxfiles.mirror_onnx import MirrorError, mirror_average_onnx

    if args.out.suffix != ".onnx":
        raise CommandError(f"--out {args.out}: give a path ending in .onnx")
    if args.out.resolve() == args.model.resolve():
        raise CommandError("--out must not be the model itself (it is read to verify the result)")
    if not args.model.is_file():
        raise CommandError(f"no model at {args.model}")
    try:
        alpha = check_alpha(args.serve_smooth)
        worst = mirror_average_onnx(args.model, args.out, alpha, output_scale=args.output_scale)
    except (MirrorError, ValueError) as exc:
        raise CommandError(str(exc)) from None
    scale = f"{args.output_scale:g} x " if args.output_scale != 1.0 else ""
    print(f"wrote {args.out}: {scale}(f(x) - f(mirror x)) / 2 of {args.model.name}, max |difference| {worst:.1e} "
          f"on random inputs" + (f"; drive_server smooths its steering with {alpha:g}" if alpha < 1 else ""))
    return 0
