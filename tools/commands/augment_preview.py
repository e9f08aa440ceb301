"""``rbc augment-preview``: a grid of augmented frames with their labels (library: :mod:`models.augment_preview`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from models.behavior import Approach, Arch, Behavior


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", action="append", required=True, metavar="DIR", help="recording directory or log")
    parser.add_argument("--behavior", choices=[b.value for b in Behavior], default="simplistic")
    parser.add_argument("--arch", choices=[a.value for a in Arch], default="shallow")
    parser.add_argument("--approach", choices=[a.value for a in Approach], default="ours")
    parser.add_argument("--out", required=True, type=Path, help="PNG file to write")
    parser.add_argument("--n", type=int, default=16, help="number of samples")
    parser.add_argument("--seed", type=int, default=0)


def run(args: argparse.Namespace) -> int:
    from models.augment_preview import write_preview

    return write_preview(args)
