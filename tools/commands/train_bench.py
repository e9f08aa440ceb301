"""``rbc train-bench``: augmentation and training throughput (library: :mod:`tools.bench.training`)."""

from __future__ import annotations

import argparse

from tools.arguments import add_pipeline_arguments


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", action="append", default=[], metavar="DIR",
                        help="recording(s) whose frames are repeated to the paper's size (default: synthetic frames)")
    add_pipeline_arguments(parser)
    parser.add_argument("--steps", type=int, default=150, help="batches per measurement")
    parser.add_argument("--repeat", type=int, default=3, help="measurements per figure (median reported)")
    parser.add_argument("--threads", type=int, help="PyTorch threads (default: as rbc train)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the synthetic frames and augmentations")


def run(args: argparse.Namespace) -> int:
    from tools.bench.training import benchmark

    return benchmark(args)
