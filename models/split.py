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

VAL_FRACTION = 0.2


class SplitKind(StrEnum):
    BLOCKS = "blocks"  # contiguous stretches of the log held out (honest on real recordings)
    RANDOM = "random"  # random frames held out (the paper's setting; optimistic at 9-15 Hz)


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
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")
        if self.block_frames < 1 or self.gap_frames < 0:
            raise ValueError(f"block frames must be >= 1 and gap frames >= 0, got {self.block_frames}, "
                             f"{self.gap_frames}")


def split_indices(n: int, seed: int, val_fraction: float = VAL_FRACTION) -> tuple[np.ndarray, np.ndarray]:
    """Random (train, validation) index arrays, each sorted so log order is kept.

    The validation share is rounded up like scikit-learn's ``train_test_split``, which gives the
    paper's Table 2 counts (12,101 -> 9,680 + 2,421).
    """
    if n < 2:
        raise ValueError(f"need at least 2 samples to split, got {n}")
    if not 0.0 < val_fraction < 1.0:
        raise ValueError(f"val_fraction must be in (0, 1), got {val_fraction}")
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
        raise ValueError(f"need at least 2 samples to split, got {n}")
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
        raise ValueError(f"no training frames left after holding out {n_val} of {n_blocks} blocks")
    return train, np.flatnonzero(is_val)


def make_split(n: int, seed: int, spec: SplitSpec) -> tuple[np.ndarray, np.ndarray]:
    """The split ``spec`` asks for, over ``n`` samples in log order."""
    if spec.kind is SplitKind.RANDOM:
        return split_indices(n, seed, spec.val_fraction)
    return block_split(n, seed, spec)
