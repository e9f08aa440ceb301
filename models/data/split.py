"""Seeded train/validation splits: the paper's random 4:1 split, and contiguous held-out blocks.

A recording at 9-15 Hz is a sequence of near-copies: with a random split every validation frame
has training neighbours a few centimetres away, so its error says how well the network
interpolates, not how it drives a stretch of road it never saw. ``block_split`` holds out whole
contiguous stretches of the log and drops a guard band of training frames on each side of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from protocol.errors import BadValue

VAL_FRACTION = 0.2


class SplitKind(StrEnum):
    BLOCKS = "blocks"  # contiguous stretches of the log held out (honest on real recordings)
    RANDOM = "random"  # random frames held out (the paper's setting; optimistic at 9-15 Hz)
    RECORDINGS = "recordings"  # whole recordings held out: what a new driver's data looks like


@dataclass(frozen=True)
class SplitSpec:
    """How samples are divided. Block and gap lengths are in frames of the log (log order)."""

    kind: SplitKind | str = SplitKind.BLOCKS
    val_fraction: float = VAL_FRACTION
    block_frames: int = 50  # ~3-6 s of driving at the simulator's 9-15 Hz
    gap_frames: int = 10  # training frames dropped on each side of a held-out block

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", SplitKind(self.kind))
        if not 0.0 < self.val_fraction < 1.0:
            raise BadValue(f"val_fraction must be in (0, 1), got {self.val_fraction}")
        if self.block_frames < 1 or self.gap_frames < 0:
            raise BadValue(f"block frames must be >= 1 and gap frames >= 0, got {self.block_frames}, "
                             f"{self.gap_frames}")


def split_indices(n: int, seed: int, val_fraction: float = VAL_FRACTION) -> tuple[np.ndarray, np.ndarray]:
    """Random (train, validation) index arrays, each sorted so log order is kept.

    The validation share is rounded up like scikit-learn's ``train_test_split``, which gives the
    paper's Table 2 counts (12,101 -> 9,680 + 2,421).
    """
    if n < 2:
        raise BadValue(f"need at least 2 samples to split, got {n}")
    if not 0.0 < val_fraction < 1.0:
        raise BadValue(f"val_fraction must be in (0, 1), got {val_fraction}")
    n_val = min(n - 1, max(1, math.ceil(n * val_fraction)))
    order = np.random.default_rng(seed).permutation(n)
    return np.sort(order[n_val:]), np.sort(order[:n_val])


def block_split(n: int, seed: int, spec: SplitSpec = SplitSpec()) -> tuple[np.ndarray, np.ndarray]:
    """(train, validation) positions: whole blocks of consecutive frames held out, chosen by ``seed``.

    The block is shortened for small logs so there are at least five of them (a short remainder joins the
    last one); round(blocks x
    val_fraction) blocks (at least one, never all) are held out. Training frames closer than the
    gap (at most a quarter block) to a held-out block are dropped from both sets.
    """
    if n < 2:
        raise BadValue(f"need at least 2 samples to split, got {n}")
    block = max(1, min(spec.block_frames, n // 5))
    gap = min(spec.gap_frames, block // 4)
    n_blocks = max(2, n // block)  # a short remainder joins the last block
    n_val = min(n_blocks - 1, max(1, round(n_blocks * spec.val_fraction)))
    held = np.random.default_rng([seed, 0xB10C]).choice(n_blocks, size=n_val, replace=False)
    block_of = np.minimum(np.arange(n) // block, n_blocks - 1)
    is_val = np.isin(block_of, held)
    near = np.zeros(n, dtype=bool)
    if gap:
        edges = np.flatnonzero(np.diff(is_val.astype(np.int8)))  # last position before each val/train border
        for e in edges:
            near[max(0, e - gap + 1):min(n, e + 1 + gap)] = True
    train = np.flatnonzero(~is_val & ~near)
    if not len(train):
        raise BadValue(f"no training frames left after holding out {n_val} of {n_blocks} blocks")
    return train, np.flatnonzero(is_val)


def recording_split(recording: np.ndarray, seed: int, spec: SplitSpec = SplitSpec(),
                    held_out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(train, validation) positions holding out whole recordings (``recording[i]``: sample i's recording id).

    ``held_out`` (bool per recording id) names them; otherwise round(recordings x val_fraction) of them (at
    least one, never all) are drawn by ``seed``. Different drivers, sessions and days differ far more than two
    stretches of one recording do, so this is the split whose figures say how a model does for someone else.
    """
    recording = np.asarray(recording)
    ids = np.unique(recording)
    if held_out is None:
        if len(ids) < 2:
            raise BadValue("split \"recordings\" needs at least two recordings (repeat --data)")
        n_val = min(len(ids) - 1, max(1, round(len(ids) * spec.val_fraction)))
        chosen = np.random.default_rng([seed, 0x12EC]).choice(ids, size=n_val, replace=False)
    else:
        chosen = np.flatnonzero(held_out)
    is_val = np.isin(recording, chosen)
    if is_val.all() or not is_val.any():
        raise BadValue("holding out recordings left no training or no validation samples")
    return np.flatnonzero(~is_val), np.flatnonzero(is_val)


def make_split(n: int, seed: int, spec: SplitSpec, recording: np.ndarray | None = None,
               held_out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The split ``spec`` asks for, over ``n`` samples in log order (``recording``: each one's recording id)."""
    if spec.kind is SplitKind.RANDOM:
        return split_indices(n, seed, spec.val_fraction)
    if spec.kind is SplitKind.RECORDINGS:
        return recording_split(np.zeros(n, int) if recording is None else recording, seed, spec, held_out)
    return block_split(n, seed, spec)
