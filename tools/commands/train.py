"""``rbc train``: balance, augment and train a model on driving logs; export it to ONNX."""

from __future__ import annotations

import argparse
import time

from tools.arguments import add_moved_to_recipe_flags
from tools.errors import CommandError

#: The recipe keys the command line may override (``--max-steps-per-epoch`` for ``max_steps_per_epoch``).
OVERRIDES = ("epochs", "seed", "max_steps_per_epoch")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from models.training.recipe import SECTION_OF, SECTIONS

    parser.add_argument("--recipe", metavar="FILE_OR_NAME",
                        help=f"what to train: a recipe file (TOML: {', '.join(f'[{s}]' for s in SECTIONS)}) or a "
                             "bundled recipe's name: laps (your own Unity laps), or a bundled model's "
                             "own (unity, simplistic, rigorous, collision, generalist, ...). Default: no recipe, the "
                             "paper's simplistic behavior with the shallow CNN, blocks split, best epoch exported; "
                             "--print shows any recipe in full")
    parser.add_argument("--data", action="append", default=[], metavar="DIR",
                        help="recording directory or driving log (repeat to combine several)")
    parser.add_argument("--val-data", action="append", default=[], metavar="DIR",
                        help="a recording held out whole for validation (repeat; implies split recordings): "
                             "e.g. one fold of other drivers' recordings (rbc data fold)")
    parser.add_argument("--out", metavar="RUN_DIR",
                        help="run directory (config, history, model); needed unless --print")
    for key in OVERRIDES:
        parser.add_argument(f"--{key.replace('_', '-')}", type=int, metavar="N",
                            help=f"instead of the recipe's [{SECTION_OF[key]}] {key}: {SECTIONS[SECTION_OF[key]][key]}")
    parser.add_argument("--threads", type=int,
                        help="PyTorch threads (default: cores - 1 for the shallow CNN, whose batches need a core of "
                             "their own; every core for PilotNet)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in RUN_DIR from its checkpoint, with the configuration stored there")
    parser.add_argument("--print", action="store_true", dest="print_recipe",
                        help="print the resolved recipe (every key, as TOML, with the command line's overrides) and "
                             "exit without training")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_moved_to_recipe_flags(parser)
    parser.epilog = ("recipe keys, by section (rbc train --recipe NAME --print writes each with what it is for and "
                     "the values it takes): " + "; ".join(f"[{section}] {', '.join(keys)}"
                                                         for section, keys in SECTIONS.items()))


def run(args: argparse.Namespace) -> int:
    from models.training.metrics import format_metrics
    from models.training.recipe import load_recipe, recipe_toml
    from models.training.train import train

    overrides = {key: getattr(args, key) for key in OVERRIDES if getattr(args, key) is not None}
    if args.print_recipe:
        print(recipe_toml(load_recipe(args.recipe, **overrides), args.recipe), end="")
        return 0
    if not args.out:
        raise CommandError("no --out", "give --out RUN_DIR, the folder the run is written to")
    if args.resume and args.recipe:
        raise CommandError("--resume continues with the configuration stored in RUN_DIR, not a recipe",
                           "drop --recipe, or train into a new --out")
    if not args.data and not args.resume:
        raise CommandError("no training data", "give at least one --data DIR (a folder rbc collect wrote)")
    config = load_recipe(args.recipe, **overrides, data=args.data, out=args.out, val_data=args.val_data,
                         threads=args.threads, progress=not args.no_progress)
    started = time.perf_counter()
    result = train(config, resume=args.resume, report=lambda line: print(line, flush=True))
    if result.info.get("rank") and not result.interrupted:  # torchrun: rank 0 reports (and exported)
        return 0
    if result.interrupted:
        print(f"interrupted; checkpoint in {result.run_dir}; continue with: rbc train --out {result.run_dir} --resume")
        return 130
    info = result.info
    print(f"held-out frames: {format_metrics(info['metrics'])}")
    by_recording = info.get("val_by_recording", [])
    if len(by_recording) > 1:
        beats = sum(m["beats_zero"] for m in by_recording)
        print(f"per held-out recording ({beats} of {len(by_recording)} beat always-0):")
        for m in by_recording:
            print(f"  {_recording_name(m['log']):<40} {format_metrics(m)}{'' if m['beats_zero'] else '  (not)'}")
    which = "the last" if info["export"] == "last" else "the lowest val MSE"
    print(f"model: {result.onnx} (epoch {info['exported_epoch']}, {which}; ONNX Runtime matches PyTorch to "
          f"{result.export_diff:.1e})")
    if info.get("loss_plot"):
        print(f"loss curve: {info['loss_plot']}")
    print(f"time: {time.perf_counter() - started:.0f} s, {result.samples_per_s:.0f} training samples/s")
    return 0


def _recording_name(log: str) -> str:
    """A recording's folder name (its log is usually ``FOLDER/driving_log.csv``)."""
    from pathlib import Path

    path = Path(log)
    return path.parent.name if path.suffix == ".csv" else path.name
