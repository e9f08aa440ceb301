"""Zero-steer balancing (Eq. 3, afresh at every pass) and the seeded 80/20 split."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from models.data.balance import balanced_pass, index_batches, zero_steer_drop_count
from models.data.behavior import BEHAVIOR_SPECS, Behavior
from models.data.split import split_indices
from protocol.facts import BEHAVIORS


@pytest.mark.parametrize(("d", "lam"), [(433, 0.7), (10, 0.7), (10, 0.8), (3, 0.7), (7, 0.0), (7, 1.0), (0, 0.8)])
def test_drop_count_is_floor_of_d_lambda(d: int, lam: float) -> None:
    assert zero_steer_drop_count(d, lam) == math.floor(round(d * lam, 9))


def test_behavior_members_are_the_protocols_behaviors() -> None:
    """Behavior is spelled out for the type checker: it must stay protocol.facts.BEHAVIORS, in order."""
    assert tuple(Behavior) == BEHAVIORS
    assert [b.name for b in Behavior] == [name.upper() for name in BEHAVIORS]
    assert set(BEHAVIOR_SPECS) == set(Behavior)


def test_paper_deletion_rates() -> None:
    assert [BEHAVIOR_SPECS[b].deletion_rate for b in Behavior] == [0.7, 0.8, 0.8]


@pytest.mark.parametrize("lam", [0.7, 0.8])
def test_each_pass_drops_exactly_floor_d_lambda_zeros_and_keeps_the_rest(lam: float) -> None:
    rng = np.random.default_rng(1)
    steering = np.where(rng.random(1000) < 0.7, 0.0, rng.uniform(-1, 1, 1000))
    zeros = np.flatnonzero(steering == 0)
    d = len(zeros)
    kept = balanced_pass(steering, lam, np.random.default_rng(2))
    assert len(np.unique(kept)) == len(kept)
    assert np.isin(np.flatnonzero(steering != 0), kept).all()  # every non-zero sample stays
    assert d - np.isin(zeros, kept).sum() == math.floor(d * lam)
    assert not np.array_equal(kept, np.sort(kept))  # shuffled


def test_passes_are_fresh_and_seeded() -> None:
    steering = np.array([0.0] * 50 + [0.3] * 10)
    rng = np.random.default_rng(7)
    first, second = balanced_pass(steering, 0.7, rng), balanced_pass(steering, 0.7, rng)
    assert set(first) != set(second)  # a different random subset of zeros each pass
    assert len(first) == len(second) == 60 - 35
    again = balanced_pass(steering, 0.7, np.random.default_rng(7))
    assert np.array_equal(first, again)


def test_index_batches_are_full_and_chain_balanced_passes() -> None:
    steering = np.array([0.0] * 100 + [0.5] * 20)
    batches = list(itertools.islice(index_batches(steering, 0.7, 32, np.random.default_rng(0)), 9))
    assert all(len(b) == 32 for b in batches)
    flat = np.concatenate(batches)[:50 * 5]  # 5 passes of 120 - 70 = 50 samples
    for p in range(5):
        one = flat[p * 50:(p + 1) * 50]
        assert len(set(one)) == 50 and (steering[one] != 0).sum() == 20


def test_balancing_that_leaves_nothing_is_an_error() -> None:
    with pytest.raises(ValueError, match="no training samples"):
        next(index_batches(np.zeros(10), 1.0, 4, np.random.default_rng(0)))


def test_split_is_seeded_80_20_like_the_paper() -> None:
    train, val = split_indices(12101, seed=3)
    assert (len(train), len(val)) == (9680, 2421)  # Table 2
    assert np.intersect1d(train, val).size == 0 and np.union1d(train, val).size == 12101
    assert np.array_equal(train, np.sort(train))
    again, _ = split_indices(12101, seed=3)
    other, _ = split_indices(12101, seed=4)
    assert np.array_equal(train, again) and not np.array_equal(train, other)
    assert [len(x) for x in split_indices(36, 0)] == [28, 8]
