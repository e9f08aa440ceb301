"""``rbc``: the project's one command line, with lazily imported subcommands.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and ``run(args) -> int``;
the table below is the only place that lists them, and a module is imported only when its
subcommand runs (so ``rbc bench`` works without torch installed).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from dataclasses import dataclass


@dataclass(frozen=True)
class Subcommand:
    name: str
    module: str
    help: str
    extra: str = ""  # the pip extra the module needs beyond the deployment packages


SUBCOMMANDS: tuple[Subcommand, ...] = (
    Subcommand("demo", "tools.demo", "start drive_server with the bundled model and drive one lap headless"),
    Subcommand("sim", "tools.sim.cli", "drive laps of the headless simulator (over the socket or in-process)"),
    Subcommand("collect", "tools.sim.collect_cli", "record a Udacity-format dataset with the autopilot"),
    Subcommand("train", "models.train_cli", "balance, augment and train a model; export it to ONNX", "train"),
    Subcommand("inspect", "models.inspect", "write analysis pictures of a training run", "train"),
    Subcommand("augment-preview", "models.preview", "write a grid of augmented frames with labels", "plots"),
    Subcommand("eval", "tools.evaluate.cli", "run the paper's robustness experiments on a model (Table 9)"),
    Subcommand("compare", "tools.evaluate.compare", "side-by-side comparison of models (Table 10)"),
    Subcommand("bench", "tools.bench", "round-trip latency benchmark of drive_server over the Unity wire"),
    Subcommand("fuzz", "tools.fuzz", "hostile-client campaign against drive_server; healthy latency beside it"),
    Subcommand("replay", "tools.replay", "replay a driving log to a drive server as the Unity simulator would"),
    Subcommand("sim-bench", "tools.sim.bench", "frames/s of the headless renderer and lap wall time"),
    Subcommand("train-bench", "models.bench", "augmentation and training throughput; projected paper run", "train"),
)


def build_parser(argv: list[str]) -> tuple[argparse.ArgumentParser, Subcommand | None]:
    parser = argparse.ArgumentParser(
        prog="rbc",
        description="Robust behavioral cloning: collect, train, deploy and evaluate driving models.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    chosen = next((c for c in SUBCOMMANDS if c.name in argv), None)
    for cmd in SUBCOMMANDS:
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        if cmd is chosen:  # import only the module that runs
            _load(cmd).add_arguments(p)
    return parser, chosen


def _load(cmd: Subcommand):
    try:
        return importlib.import_module(cmd.module)
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.split(".")[0] in {"torch", "onnx", "matplotlib", "tqdm"}:
            hint = f'pip install "robust-behavioral-cloning[{cmd.extra or "train"}]"'
            sys.exit(f"rbc {cmd.name}: needs the package {exc.name!r}; install it with: {hint}")
        raise


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser, chosen = build_parser(argv)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s", datefmt="%H:%M:%S")
    if chosen is None or args.command is None:
        parser.print_help()
        return 2
    try:
        return int(_load(chosen).run(args) or 0)
    except KeyboardInterrupt:
        logging.getLogger("rbc").warning("interrupted")
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
