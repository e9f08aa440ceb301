"""What a training run says and draws for the person who started it: what it read, kept and held out, the
network and its schedule in the field's words, and its loss curve (``loss.png``)."""

from __future__ import annotations

import logging
from pathlib import Path

from models.data.split import SplitKind
from models.data.trainingdata import PreparedData
from models.networks import runfiles
from models.training.train_config import TrainConfig

log = logging.getLogger(__name__)

#: The networks as the field calls them (``arch`` in a recipe).
NETWORK_NAMES = {"shallow": "the paper's shallow CNN", "shallow-wide": "the wider shallow CNN",
                 "pilotnet": "NVIDIA's PilotNet"}


def describe_data(data: PreparedData, config: TrainConfig) -> list[str]:
    """What a run read, kept and held out, in three lines of the field's words."""
    c = data.counts
    lines = [f"read: {c['rows']} rows of {_count(c['recordings'], 'recording')}; "
             f"{c['skipped']} bad rows or missing images, {c['unreadable']} unreadable frames"]
    stride = "every row" if c.get("stride", 1) == 1 else f"every {_ordinal(c['stride'])} row"
    slow = (f", leaving out {c['slow']} below {config.min_speed:g} {config.min_speed_unit}"
            if config.min_speed > 0 else "")
    if config.drop_turnround:
        slow += f", leaving out {c.get('turnround', 0)} of turns round"
    lines.append(f"used: {stride}{slow}: {c['kept']} frames")
    kind = SplitKind(data.split.kind)
    if kind is SplitKind.RECORDINGS:
        how = f"{c['val_recordings']} of {c['recordings']} recordings held out whole"
    elif kind is SplitKind.BLOCKS:
        how = f"held out in blocks of {data.split.block_frames}"
        if c.get("gap"):
            how += f" ({c['gap']} next to them left out)"
    else:
        how = "held out at random"
    lines.append(f"split: {c['train']} frames for training, {c['val']} {how}")
    return lines


def _ordinal(n: int) -> str:
    return f"{n}{'th' if 10 <= n % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(n % 10, 'th')}"


def describe_network(config: TrainConfig, parameters: int, epochs: int, steps: int) -> str:
    """The network and the training schedule, in one line."""
    what = NETWORK_NAMES.get(config.arch, config.arch)
    if config.behavior != "simplistic":
        what += f", the {config.behavior} behavior"
    if config.approach != "ours":
        what += f", {config.approach}'s approach"
    return (f"network: {what} ({parameters:,} weights); {_count(epochs, 'epoch')} of {_count(steps, 'step')} of "
            f"{config.batch_size} samples")


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def draw_loss(run_dir: Path, history: list[dict[str, float]], exported_epoch: int | None = None) -> Path | None:
    """``loss.png`` in the run folder: the training and held-out MSE per epoch (None without matplotlib)."""
    try:
        from models.training.inspection import plot_loss

        rows = [runfiles.EpochRow(int(h["epoch"]), h["train_loss"], h["val_loss"], h["seconds"]) for h in history]
        return plot_loss(run_dir, rows, exported_epoch)
    except ImportError as exc:  # the train extra brings matplotlib; a bare torch install may lack it
        log.warning("loss curve not drawn: %s (pip install -e \".[train]\")", exc)
        return None
