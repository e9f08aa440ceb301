"""``rbc``: the project's one command line, dispatched on its first positional argument.

Each subcommand is one module of :mod:`tools.commands` exposing ``add_arguments(parser)`` and
``run(args) -> int``; the table below is the only place that lists them. Only the module of the
chosen subcommand is imported (so ``rbc bench`` works without torch installed), and the choice is
the first argument that is not an option: ``rbc train --out sim`` trains, whatever the flags say.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import logging
import os
import sys
from dataclasses import dataclass
from importlib import metadata
from types import ModuleType

from protocol.helpformat import DefaultsHelpFormatter
from tools.console import console
from tools.errors import is_user_error, one_line, remove_new_empty_outputs, snapshot

#: Options of ``rbc`` itself, allowed before the subcommand.
GLOBAL_FLAGS = ("-v", "--verbose", "-h", "--help", "--version")
#: The packages of each optional extra (as in pyproject.toml): checked before a command that needs them runs.
EXTRAS = {"train": ("torch", "onnx", "matplotlib", "tqdm"), "plots": ("matplotlib",), "onnx": ("onnx",)}


@dataclass(frozen=True)
class Subcommand:
    name: str
    module: str
    help: str
    extra: str = ""  # the pip extra the module needs beyond the deployment packages


SUBCOMMANDS: tuple[Subcommand, ...] = (
    Subcommand("demo", "tools.commands.demo", "start drive_server with the bundled model and drive one lap headless"),
    Subcommand("sim", "tools.commands.sim", "drive laps of the headless simulator (over the socket or in-process)"),
    Subcommand("collect", "tools.commands.collect", "record a Udacity-format dataset with the autopilot"),
    Subcommand("train", "tools.commands.train", "balance, augment and train a model; export it to ONNX", "train"),
    Subcommand("inspect", "tools.commands.inspect_run", "write analysis pictures of a training run", "train"),
    Subcommand("augment-preview", "tools.commands.augment_preview", "write a grid of augmented frames with labels",
               "plots"),
    Subcommand("eval", "tools.commands.eval", "run the paper's robustness experiments on a model (Table 9)"),
    Subcommand("compare", "tools.commands.compare", "side-by-side comparison of models (Table 10)"),
    Subcommand("bench", "tools.commands.bench", "round-trip latency benchmark of drive_server over the Unity wire"),
    Subcommand("data", "tools.commands.data", "real Unity recordings: stats, clean, fetch the public ones"),
    Subcommand("video", "tools.commands.video",
               "a browser-playable video of a recording (drive_server --record, rbc collect, Unity)"),
    Subcommand("fuzz", "tools.commands.fuzz",
               "hostile-client campaign against drive_server; healthy latency beside it"),
    Subcommand("realism", "tools.commands.realism",
               "image statistics of headless frames against real ones, per band, with a picture"),
    Subcommand("soak", "tools.commands.soak",
               "drive_server for hours under a steady mix of clients: what leaked or drifted (JSON, plot)"),
    Subcommand("replay", "tools.commands.replay",
               "replay a driving log to a drive server as the Unity simulator would"),
    Subcommand("score", "tools.commands.score",
               "open-loop scores of models on a recorded driving log (e.g. real Unity frames)"),
    Subcommand("import-peer", "tools.commands.import_peer", "import a peer's Keras 1 PilotNet .h5 as ONNX", "train"),
    Subcommand("mirror", "tools.commands.mirror",
               "an ONNX model answering (f(x) - f(mirror x)) / 2: its left-right lean cancelled", "onnx"),
    Subcommand("monitor", "tools.commands.monitor",
               "a misbehaviour monitor for a model: trained and calibrated on nominal driving, attached to its file",
               "train"),
    Subcommand("ensemble", "tools.commands.ensemble",
               "several ONNX models (e.g. one recipe, several seeds) averaged into one file", "onnx"),
    Subcommand("drive-log", "tools.commands.drive_log",
               "closed loop on a recorded real drive: the model sees re-projected recorded frames (DAVE-2)"),
    Subcommand("world", "tools.commands.world", "write procedural worlds (track files) or a contact sheet of them"),
    Subcommand("sim-bench", "tools.commands.sim_bench", "frames/s of the headless renderer and lap wall time"),
    Subcommand("env-bench", "tools.commands.env_bench", "steps/s of the Gymnasium environment rbc/Drive-v0 per core"),
    Subcommand("dagger", "tools.commands.dagger",
               "DAgger on the headless simulator (the autopilot labels what the learner visits), or its BC baseline",
               "train"),
    Subcommand("train-bench", "tools.commands.train_bench", "augmentation and training throughput; projected paper run",
               "train"),
    Subcommand("model-card", "tools.commands.model_card",
               "write a model's card and the resolved recipe beside it, from its training run"),
)
BY_NAME = {c.name: c for c in SUBCOMMANDS}


def find_subcommand(argv: list[str]) -> tuple[Subcommand | None, int]:
    """The subcommand named by the first positional argument and its index (None, -1 if there is none).

    Only ``rbc``'s own flags may come before it; an unknown name is left to argparse to report.
    """
    for i, arg in enumerate(argv):
        if arg in GLOBAL_FLAGS:
            continue
        return BY_NAME.get(arg), i
    return None, -1


def top_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rbc",
        description="Robust behavioral cloning: collect, train, deploy and evaluate driving models.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging, and tracebacks for errors")
    parser.add_argument("--version", action="store_true", help="print the version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for cmd in SUBCOMMANDS:
        sub.add_parser(cmd.name, help=cmd.help, description=cmd.help, add_help=False)
    return parser


def load(cmd: Subcommand) -> ModuleType:
    """Import a subcommand's module; a missing optional package exits with its install line."""
    try:
        return importlib.import_module(cmd.module)
    except ModuleNotFoundError as exc:
        root = (exc.name or "").split(".")[0]
        extra = cmd.extra or next((e for e, names in EXTRAS.items() if root in names), "")
        if extra:
            sys.exit(f'rbc {cmd.name}: error: needs the package {root!r} (hint: pip install -e ".[{extra}]")')
        raise


def subcommand_parser(cmd: Subcommand, module: ModuleType) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=f"rbc {cmd.name}", description=cmd.help,
                                     formatter_class=DefaultsHelpFormatter)
    module.add_arguments(parser)
    return parser


#: Argument names of output paths: created by a command, removed again if it fails leaving them empty.
OUTPUT_ARGS = ("out", "json", "map", "strip", "video", "sheet", "plot")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    cmd, index = find_subcommand(argv)
    if any(a == "--version" for a in argv[: index if index >= 0 else len(argv)]):
        print(f"rbc {package_version()}")
        return 0
    if cmd is None:
        parser = top_parser()
        if index < 0:
            parser.parse_args(argv)  # -h prints the help and exits
            parser.print_help()
            return 2
        parser.parse_args(argv[: index + 1])  # reports the unknown command and exits 2
        return 2
    verbose = any(a in ("-v", "--verbose") for a in argv[:index])
    if any(a in ("-h", "--help") for a in argv[:index]):
        top_parser().print_help()
        return 0
    missing = missing_packages(cmd)
    if missing:
        print(f"rbc {cmd.name}: error: needs the package(s) {', '.join(missing)} "
              f'(hint: pip install -e ".[{cmd.extra}]")', file=sys.stderr)
        return 2
    module = load(cmd)
    args = subcommand_parser(cmd, module).parse_args(argv[index + 1:])
    args.command, args.verbose = cmd.name, verbose or getattr(args, "verbose", False)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s", datefmt="%H:%M:%S")
    created = snapshot(getattr(args, name, None) for name in OUTPUT_ARGS)
    try:
        with console():
            return int(module.run(args) or 0)
    except KeyboardInterrupt:
        logging.getLogger("rbc").warning("interrupted")
        remove_new_empty_outputs(created)
        return 130
    except Exception as exc:  # the error boundary: see tools.errors
        remove_new_empty_outputs(created)
        if isinstance(exc, BrokenPipeError) and _stdout_gone():
            return 141  # the reader of our output left (`rbc data fold A | head`): quiet, as any Unix tool
        if args.verbose or not is_user_error(exc):
            raise
        print(one_line(cmd.name, exc), file=sys.stderr)
        return 2


def _stdout_gone() -> bool:
    """Whether standard output is a pipe whose reader has gone away (nothing more can be written to it)."""
    import select

    if not hasattr(select, "poll"):
        return False
    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        gone = any(event & select.POLLERR for _, event in poller.poll(0))
    except (OSError, ValueError):
        return False
    if gone:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # so the flush at exit is quiet too
    return gone


def package_version() -> str:
    try:
        return metadata.version("robust-behavioral-cloning")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def missing_packages(cmd: Subcommand) -> list[str]:
    """The packages of ``cmd``'s extra that are not installed (checked before anything runs)."""
    if not cmd.extra:
        return []
    return [name for name in EXTRAS[cmd.extra] if importlib.util.find_spec(name) is None]


if __name__ == "__main__":
    raise SystemExit(main())
