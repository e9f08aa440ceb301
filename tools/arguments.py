"""Flags that several commands share, defined once so every command names and explains them the same way."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from protocol import SpeedUnit
from protocol.errors import BadValue


def add_pipeline_arguments(parser: argparse.ArgumentParser) -> None:
    """``--behavior``, ``--arch``, ``--approach``: which of the paper's training pipelines."""
    from models.data.behavior import Approach, Arch, Behavior
    from models.training.train_config import TrainConfig

    parser.add_argument("--behavior", choices=[b.value for b in Behavior], default=TrainConfig.behavior,
                        help="driving behavior: sets zero-steer balancing, augmentations and epochs (paper Tables 4-6)")
    parser.add_argument("--arch", choices=[a.value for a in Arch], default=TrainConfig.arch,
                        help="network: the paper's shallow CNN, NVIDIA's PilotNet, or the shallow CNN at 128x64 "
                             "with twice the filters (shallow-wide, not in the paper)")
    parser.add_argument("--approach", choices=[a.value for a in Approach], default=TrainConfig.approach,
                        help="ours: the paper's balancing + augmentation; nvidia: crop/YUV, no balancing")


def add_speed_unit_argument(parser: argparse.ArgumentParser, default: str, what: str) -> None:
    """``--speed-unit`` (old spelling ``--telemetry-speed-unit`` kept as an alias): mph or km/h."""
    parser.add_argument("--speed-unit", "--telemetry-speed-unit", dest="speed_unit",
                        choices=[u.value for u in SpeedUnit], default=default,
                        help=f"unit of {what}: mph like the stock Udacity simulator, or kmh like the paper's")


def add_smooth_argument(parser: argparse.ArgumentParser) -> None:
    """``--smooth ALPHA``: the model's steering smoothed over the frames as ``drive_server --smooth`` does."""
    parser.add_argument("--smooth", type=float, default=None, metavar="ALPHA",
                        help="smooth the model's steering over the frames as drive_server --smooth does: each frame "
                             "ALPHA of the new output and 1 - ALPHA of the last, 0 < ALPHA <= 1, 1: off (default: "
                             "what the model's metadata asks for, as drive_server; off for a model without)")


def add_gain_argument(parser: argparse.ArgumentParser) -> None:
    """``--gain G``: the model's steering multiplied as ``drive_server --gain`` does."""
    parser.add_argument("--gain", type=float, default=None, metavar="G",
                        help="multiply the model's steering by G (0.1..2) as drive_server --gain does (default: what "
                             "the model's metadata asks for, as drive_server; 1 for a model without)")


def serving_gain(args: argparse.Namespace) -> float | None:
    """The ``--gain`` value (None: the model's own), or a CommandError in one line."""
    from drive_server.serving.settings import check_gain

    return _checked("--gain", args.gain, check_gain)


def _checked(flag: str, value: float | None, check: Callable[[float], float]) -> float | None:
    """``value`` through ``check`` (None stays None: the model's own), a ValueError as a one-line CommandError."""
    from tools.errors import CommandError

    try:
        return None if value is None else check(value)
    except ValueError as exc:
        raise CommandError(f"{flag}: {exc}") from None


def add_loop_rule_arguments(parser: argparse.ArgumentParser) -> None:
    """``--lane``, ``--max-offset``, ``--handback``: when a person takes over in the closed loop on a recording
    (``rbc drive-log``, ``rbc data crossval``) and how long they drive; defaults and ranges are ``LoopRules``'."""
    from tools.drivelog.loop import LoopRules

    parser.add_argument("--lane", choices=("road", "path"), default=LoopRules.lane,
                        help="closed loop: road: a person takes over when the car's side passes an edge line of the "
                             "road, found in each recorded frame; path: when the car is --max-offset from the "
                             "driver's own line (DAVE-2) (default %(default)s)")
    parser.add_argument("--max-offset", type=float, default=LoopRules.max_offset_m, metavar="M",
                        help="with --lane path: metres off the driver's line at which a person takes over (DAVE-2: "
                             "1 m) (default %(default)s)")
    parser.add_argument("--handback", type=float, default=LoopRules.handback_s, metavar="S",
                        help="after a take-over the person drives the recorded path S seconds before handing back "
                             f"(the {LoopRules.seconds_per_intervention:g} s Eq. 2 charges for it; 0: at once, as "
                             "DAVE-2's simulator) (default %(default)s)")


def smooth_alpha(args: argparse.Namespace) -> float | None:
    """The ``--smooth`` value (None: the model's own), or a CommandError in one line."""
    from drive_server.serving.smoothing import check_alpha

    return _checked("--smooth", args.smooth, check_alpha)


def parse_speed(text: str, default_unit: str) -> tuple[float, str]:
    """``"5mph"``, ``"8 kmh"``, ``"8km/h"`` or a bare number (in ``default_unit``) -> (value, unit)."""
    import re

    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*(mph|kmh|km/h)?\s*", str(text).lower())
    if not m:
        raise BadValue(f"--min-speed {text!r}: give a number with an optional unit, e.g. 5mph or 8kmh")
    unit = (m.group(2) or default_unit).replace("km/h", "kmh")
    return float(m.group(1)), unit


def add_camera_argument(parser: argparse.ArgumentParser, default: str | None) -> None:
    """``--camera``: which camera rig the headless simulator renders with (None: the model's)."""
    from tools.sim.render.camera import RIGS

    said = (f"default {default}" if default else
            "default: the rig the model learnt from, classic for models made before the unity rig; unity "
            "without --model")
    parser.add_argument("--camera", choices=tuple(RIGS), default=default,
                        help="camera rig: unity (the real simulator's: horizon at row 64, height 1.40 m, its "
                             "bonnet from row 137) or classic (the first headless camera, the paper's tables) "
                             f"({said})")


def add_vehicle_argument(parser: argparse.ArgumentParser, default: str) -> None:
    """``--vehicle``: which car model the headless simulator drives."""
    from tools.sim.vehicle.kinematic import VEHICLE_KINDS

    parser.add_argument("--vehicle", choices=VEHICLE_KINDS, default=default,
                        help="car model: dynamic single-track with tyre slip, or the kinematic bicycle "
                             "(default %(default)s)")


class MovedToRecipe(argparse.Action):
    """A flag whose setting now lives in recipe files: still recognised, so an old command line stops with one
    line saying where the setting went instead of argparse's "unrecognized arguments"."""

    def __init__(self, option_strings: list[str], dest: str, where: str, **kwargs: object) -> None:
        super().__init__(option_strings, dest, nargs="?", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        self.where = where

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        parser.exit(2, f"{parser.prog}: error: {option_string} {self.where}\n")


def add_moved_to_recipe_flags(parser: argparse.ArgumentParser) -> None:
    """Every recipe key as a hidden flag (``--edge-gain`` for ``[augmentation] edge_gain``, and the old names of
    renamed and removed ones) that exits 2 with one line saying where it went; flags the parser has stay its own."""
    from models.training.recipe import SECTION_OF
    from models.training.train_config import REMOVED, RENAMED

    command = parser.prog
    moved = {key: f"set [{section}] {key}" for key, section in SECTION_OF.items()}
    moved |= {old: f"set [{SECTION_OF[new]}] {new}" for old, new in RENAMED.items()}
    moved["min_speed"] = "set [data] min_speed and min_speed_unit (e.g. 5.0 and \"mph\")"
    for key, where in moved.items():
        flag = "--" + key.replace("_", "-")
        if flag not in parser._option_string_actions:
            parser.add_argument(flag, action=MovedToRecipe, where=f"moved into recipes: {where} in a recipe file "
                                f"({command} --recipe FILE; rbc train --recipe unity --print shows one)")
    for key in REMOVED:
        parser.add_argument("--" + key.replace("_", "-"), action=MovedToRecipe,
                            where="was removed: it was measured useless (docs/experiments.md)")


def add_monitor_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """``--monitor off|warn|act``: drive_server's flag of the same name, for a command that drives a model."""
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy

    parser.add_argument("--monitor", choices=[m.value for m in MonitorMode], default=MonitorPolicy.mode.value,
                        help=f"{what}: the model's misbehaviour monitor, if its file carries one, as drive_server "
                             "--monitor: off; warn (scored and reported, driving unchanged); act (also slows down "
                             "on a warning and stops on an alarm) (default %(default)s)")
