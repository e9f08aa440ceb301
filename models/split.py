"""Seeded train/validation split (paper section 3.1.2: 4:1)."""

from __future__ import annotations

import math

import numpy as np

VAL_FRACTION = 0.2


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
