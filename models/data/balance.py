"""Zero-steer balancing (paper section 3.1.3.2, Eq. 3) and the stream of training passes.

Keyboard driving records exactly zero steering most of the time. At EVERY pass over the training
data, D = floor(d * lambda) of the d zero-steer samples are dropped at random, so over many passes
almost every recorded frame is still seen while each pass is far less biased towards going straight.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from protocol.errors import BadValue


def zero_steer_drop_count(d: int, deletion_rate: float) -> int:
    """Eq. 3: D = floor(d * lambda)."""
    if not 0.0 <= deletion_rate <= 1.0:
        raise BadValue(f"deletion rate must be in [0, 1], got {deletion_rate}")
    return math.floor(d * deletion_rate + 1e-9)


def balanced_pass(steering: np.ndarray, deletion_rate: float, rng: np.random.Generator,
                  groups: np.ndarray | None = None) -> np.ndarray:
    """Indices of one pass: all non-zero samples plus the zero-steer samples that survive, shuffled.

    ``groups`` (a recording id per sample): each recording then gives a pass at most as many samples as the
    median recording does (:func:`group_cap`), drawn afresh each pass, so one long recording does not
    dominate the fit while over many passes all of its frames are still seen.
    """
    steering = np.asarray(steering)
    zeros = np.flatnonzero(steering == 0.0)
    drop = zero_steer_drop_count(len(zeros), deletion_rate)
    keep = np.ones(len(steering), dtype=bool)
    if drop:
        keep[rng.choice(zeros, size=drop, replace=False)] = False
    if groups is not None:
        groups = np.asarray(groups)
        cap = group_cap(groups[keep])
        for g in np.unique(groups):
            members = np.flatnonzero(keep & (groups == g))
            if len(members) > cap:
                keep[rng.choice(members, size=len(members) - cap, replace=False)] = False
    return rng.permutation(np.flatnonzero(keep))


def group_cap(groups: np.ndarray) -> int:
    """Most samples one group may give a pass: the median group size (at least 1)."""
    _, counts = np.unique(groups, return_counts=True)
    return max(1, int(np.median(counts))) if len(counts) else 1


def index_batches(steering: np.ndarray, deletion_rate: float, batch_size: int,
                  rng: np.random.Generator, groups: np.ndarray | None = None) -> Iterator[np.ndarray]:
    """Endless full batches of training indices; a fresh balanced pass starts whenever one is used up.

    Batches run across pass boundaries so every step trains on ``batch_size`` samples, as the
    paper's generator did (steps per epoch = ceil(n / batch) * loops, independent of balancing).
    """
    if len(steering) == 0:
        raise BadValue("no training samples")
    pending = np.empty(0, dtype=np.int64)
    while True:
        while len(pending) < batch_size:
            one_pass = balanced_pass(steering, deletion_rate, rng, groups)
            if len(one_pass) == 0:
                raise BadValue("balancing leaves no training samples")
            pending = np.concatenate([pending, one_pass])
        yield pending[:batch_size]
        pending = pending[batch_size:]
