"""Zero-steer balancing (paper section 3.1.3.2, Eq. 3) and the stream of training passes.

Keyboard driving records exactly zero steering most of the time. At EVERY pass over the training
data, D = floor(d * lambda) of the d zero-steer samples are dropped at random, so over many passes
almost every recorded frame is still seen while each pass is far less biased towards going straight.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np


def zero_steer_drop_count(d: int, deletion_rate: float) -> int:
    """Eq. 3: D = floor(d * lambda)."""
    if not 0.0 <= deletion_rate <= 1.0:
        raise ValueError(f"deletion rate must be in [0, 1], got {deletion_rate}")
    return math.floor(d * deletion_rate + 1e-9)


def balanced_pass(steering: np.ndarray, deletion_rate: float, rng: np.random.Generator) -> np.ndarray:
    """Indices of one pass: all non-zero samples plus the zero-steer samples that survive, shuffled."""
    steering = np.asarray(steering)
    zeros = np.flatnonzero(steering == 0.0)
    drop = zero_steer_drop_count(len(zeros), deletion_rate)
    keep = np.ones(len(steering), dtype=bool)
    if drop:
        keep[rng.choice(zeros, size=drop, replace=False)] = False
    return rng.permutation(np.flatnonzero(keep))


def index_batches(steering: np.ndarray, deletion_rate: float, batch_size: int,
                  rng: np.random.Generator) -> Iterator[np.ndarray]:
    """Endless full batches of training indices; a fresh balanced pass starts whenever one is used up.

    Batches run across pass boundaries so every step trains on ``batch_size`` samples, as the
    paper's generator did (steps per epoch = ceil(n / batch) * loops, independent of balancing).
    """
    if len(steering) == 0:
        raise ValueError("no training samples")
    pending = np.empty(0, dtype=np.int64)
    while True:
        while len(pending) < batch_size:
            one_pass = balanced_pass(steering, deletion_rate, rng)
            if len(one_pass) == 0:
                raise ValueError("balancing leaves no training samples")
            pending = np.concatenate([pending, one_pass])
        yield pending[:batch_size]
        pending = pending[batch_size:]
