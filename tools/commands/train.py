"""``rbc train``: balance, augment and train a model on driving logs; export it to ONNX."""

from __future__ import annotations

import argparse

from models.train_config import TrainConfig
from tools.arguments import add_pipeline_arguments
from tools.errors import CommandError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", action="append", default=[], metavar="DIR",
                        help="recording directory or driving log (repeat to combine several)")
    add_pipeline_arguments(parser)
    parser.add_argument("--out", required=True, metavar="RUN_DIR", help="run directory (config, history, model)")
    parser.add_argument("--epochs", type=int, help="default: the paper's 5 / 10 / 5 by behavior")
    parser.add_argument("--aug-loops", type=int, default=TrainConfig.aug_loops,
                        help="augmentation loops per epoch: each pass over the training data draws new "
                             "augmentations (chi of the paper; default %(default)s)")
    parser.add_argument("--batch-size", type=int, default=TrainConfig.batch_size, help="default %(default)s")
    parser.add_argument("--seed", type=int, default=TrainConfig.seed, help="split, balancing, augmentation and "
                        "initialisation seed (default %(default)s)")
    parser.add_argument("--max-steps-per-epoch", type=int, help="cap steps per epoch (quick runs)")
    parser.add_argument("--threads", type=int,
                        help="PyTorch threads (default: cores - 1 for the shallow CNN, whose batches need a core of "
                             "their own; every core for PilotNet)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in RUN_DIR from its checkpoint, with the configuration stored there")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from models.train import train

    if not args.data and not args.resume:
        raise CommandError("no training data", "give at least one --data DIR (a folder rbc collect wrote)")
    config = TrainConfig(data=args.data, out=args.out, behavior=args.behavior, arch=args.arch,
                         approach=args.approach, epochs=args.epochs, aug_loops=args.aug_loops,
                         batch_size=args.batch_size, seed=args.seed, max_steps_per_epoch=args.max_steps_per_epoch,
                         threads=args.threads, progress=not args.no_progress)
    result = train(config, resume=args.resume)
    for row in result.history:
        print(f"epoch {row['epoch']}: train MSE {row['train_loss']:.5f}  val MSE {row['val_loss']:.5f}  "
              f"{row['seconds']:.0f} s")
    if result.interrupted:
        print(f"interrupted; checkpoint in {result.run_dir}; continue with: rbc train --out {result.run_dir} --resume")
        return 130
    print(f"model: {result.onnx} (val MSE {result.val_loss:.5f}; ONNX Runtime matches PyTorch to "
          f"{result.export_diff:.1e}); {result.samples_per_s:.0f} training samples/s")
    return 0
