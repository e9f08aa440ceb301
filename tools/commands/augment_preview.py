"""``rbc augment-preview``: a grid of augmented frames with their labels (library: :mod:`models.augment_preview`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.arguments import add_pipeline_arguments, add_preprocess_arguments, add_yaw_arguments


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", action="append", required=True, metavar="DIR", help="recording directory or log")
    add_pipeline_arguments(parser)
    add_preprocess_arguments(parser)
    add_yaw_arguments(parser)
    parser.add_argument("--out", required=True, type=Path, help="PNG file to write")
    parser.add_argument("--n", type=int, default=16, help="number of samples")
    parser.add_argument("--seed", type=int, default=0, help="which samples and augmentations are drawn")


def run(args: argparse.Namespace) -> int:
    from models.augment_preview import write_preview
    from tools.arguments import preprocess_options

    return write_preview(args, preprocess_options(args) | {k: getattr(args, k) for k in ("yaw_aug", "yaw_range",
                                                                                           "yaw_gain")})
