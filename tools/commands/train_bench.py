"""``rbc train-bench``: augmentation and training throughput (library: :mod:`tools.bench.training`, whose
:class:`~tools.bench.training.TrainBenchPlan` holds this command's defaults)."""

from __future__ import annotations

import argparse

from tools.arguments import add_pipeline_arguments
from tools.bench.training import TrainBenchPlan, benchmark

PLAN = TrainBenchPlan()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", action="append", default=[], metavar="DIR",
                        help="recording(s) whose frames are repeated to the paper's size (default: synthetic frames)")
    add_pipeline_arguments(parser)
    parser.add_argument("--steps", type=int, default=PLAN.steps, help="batches per measurement")
    parser.add_argument("--repeat", type=int, default=PLAN.repeat, help="measurements per figure (median reported)")
    parser.add_argument("--threads", type=int, default=PLAN.threads, help="PyTorch threads (default: as rbc train)")
    parser.add_argument("--seed", type=int, default=PLAN.seed, help="seed of the synthetic frames and augmentations")


def run(args: argparse.Namespace) -> int:
    return benchmark(TrainBenchPlan(data=tuple(args.data), behavior=args.behavior, arch=args.arch,
                                    approach=args.approach, steps=args.steps, repeat=args.repeat,
                                    threads=args.threads, seed=args.seed))
