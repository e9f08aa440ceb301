"""Flags that several commands share, defined once so every command names and explains them the same way."""

from __future__ import annotations

import argparse

from protocol import SpeedUnit


def add_pipeline_arguments(parser: argparse.ArgumentParser) -> None:
    """``--behavior``, ``--arch``, ``--approach``: which of the paper's training pipelines."""
    from models.training.behavior import Approach, Arch, Behavior
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


def smooth_alpha(args: argparse.Namespace) -> float | None:
    """The ``--smooth`` value (None: the model's own), or a CommandError in one line."""
    from drive_server.smoothing import check_alpha
    from tools.errors import CommandError

    try:
        return None if args.smooth is None else check_alpha(args.smooth)
    except ValueError as exc:
        raise CommandError(f"--smooth: {exc}") from None


#: A documented region of interest for real Unity recordings with the car's bonnet in view: rows 64..136 of
#: the 320x160 frame drop the sky and far scenery above and the bonnet (from row ~137 down) below.
BONNET_CROP = (64, 136)


def add_preprocess_arguments(parser: argparse.ArgumentParser) -> None:
    """Crop (carried in the model's contract) and brightness-augmentation strength, for train and previews."""
    from drive_server.contract import DECODE_REDUCTIONS
    from models.training.train_config import SCALE_BRIGHTNESS_RANGE, TrainConfig

    parser.add_argument("--crop-top", type=int, default=TrainConfig.crop_top, metavar="ROW",
                        help="first row of the 320x160 frame the network sees (default: the approach's, 0 for ours, "
                             f"60 for nvidia; real Unity recordings with the bonnet in view: {BONNET_CROP[0]})")
    parser.add_argument("--crop-bottom", type=int, default=TrainConfig.crop_bottom, metavar="ROW",
                        help="row after the last one the network sees (default: the approach's, 160; with the "
                             f"bonnet in view: {BONNET_CROP[1]})")
    parser.add_argument("--decode-reduce", type=int, choices=DECODE_REDUCTIONS, default=TrainConfig.decode_reduce,
                        metavar="N", help="decode camera frames at 1/N size, in training and in the drive server (the "
                        "model's contract says so): 2 halves the decode and resize cost even where the crop then has "
                        "fewer rows than the network; 0: the largest that keeps the network's resolution "
                        "(default %(default)s)")
    parser.add_argument("--brightness-mode", choices=("add", "scale"), default=TrainConfig.brightness_mode,
                        help="add: the paper's p + beta (grey levels); scale: p * (1 + beta), relative to the frame's "
                             "own brightness, so dark frames are not blacked out")
    parser.add_argument("--brightness-range", type=float, default=TrainConfig.brightness_range, metavar="R",
                        help="beta ~ U(-R, R) (default: 100 grey levels for add, as in the paper; 50 for nvidia; "
                             f"{SCALE_BRIGHTNESS_RANGE} for scale)")


def preprocess_options(args: argparse.Namespace) -> dict:
    """The ``TrainConfig`` fields set by :func:`add_preprocess_arguments`."""
    return {k: getattr(args, k) for k in ("crop_top", "crop_bottom", "decode_reduce", "brightness_mode",
                                          "brightness_range")}


def parse_speed(text: str, default_unit: str) -> tuple[float, str]:
    """``"5mph"``, ``"8 kmh"``, ``"8km/h"`` or a bare number (in ``default_unit``) -> (value, unit)."""
    import re

    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*(mph|kmh|km/h)?\s*", str(text).lower())
    if not m:
        raise ValueError(f"--min-speed {text!r}: give a number with an optional unit, e.g. 5mph or 8kmh")
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


def add_yaw_arguments(parser: argparse.ArgumentParser) -> None:
    """``--yaw-aug/--yaw-range/--yaw-gain``: the turned-camera augmentation (rbc train, rbc augment-preview)."""
    from models.training.train_config import TrainConfig

    parser.add_argument("--yaw-aug", type=float, default=TrainConfig.yaw_aug, metavar="P",
                        help="share of samples seen from the car turned by psi ~ U(-R, R) degrees (an exact "
                             "re-projection for the real simulator's camera), labelled theta - G psi: teaches the "
                             "heading feedback a closed loop needs; not in the paper (default %(default)s: off)")
    parser.add_argument("--yaw-range", type=float, default=TrainConfig.yaw_range, metavar="R",
                        help="largest turn of --yaw-aug, degrees (default %(default)s)")
    parser.add_argument("--yaw-gain", type=float, default=TrainConfig.yaw_gain, metavar="G",
                        help="how much of a turn --yaw-aug's label steers back at once (default %(default)s: "
                             "all of it, aiming along the road again)")
