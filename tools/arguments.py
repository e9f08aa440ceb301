"""Flags that several commands share, defined once so every command names and explains them the same way."""

from __future__ import annotations

import argparse

from protocol import SpeedUnit


def add_pipeline_arguments(parser: argparse.ArgumentParser) -> None:
    """``--behavior``, ``--arch``, ``--approach``: which of the paper's training pipelines."""
    from models.behavior import Approach, Arch, Behavior
    from models.train_config import TrainConfig

    parser.add_argument("--behavior", choices=[b.value for b in Behavior], default=TrainConfig.behavior,
                        help="driving behavior: sets zero-steer balancing, augmentations and epochs (paper Tables 4-6)")
    parser.add_argument("--arch", choices=[a.value for a in Arch], default=TrainConfig.arch,
                        help="network: the paper's shallow CNN or NVIDIA's PilotNet")
    parser.add_argument("--approach", choices=[a.value for a in Approach], default=TrainConfig.approach,
                        help="ours: the paper's balancing + augmentation; nvidia: crop/YUV, no balancing")


def add_speed_unit_argument(parser: argparse.ArgumentParser, default: str, what: str) -> None:
    """``--speed-unit`` (old spelling ``--telemetry-speed-unit`` kept as an alias): mph or km/h."""
    parser.add_argument("--speed-unit", "--telemetry-speed-unit", dest="speed_unit",
                        choices=[u.value for u in SpeedUnit], default=default,
                        help=f"unit of {what}: mph like the stock Udacity simulator, or kmh like the paper's")
