"""The per-frame ring behind the stage timings and the monitor's figures: grows to its capacity, keeps the last
rows, and a ring rebuilt from saved rows (a worker's hand-back) goes on recording."""

from __future__ import annotations

import numpy as np

from drive_server.observing.monitor_stats import MonitorTally
from drive_server.observing.ring import SampleRing
from drive_server.observing.stats import LatencyStats


def test_the_ring_grows_to_its_capacity_then_keeps_the_last_rows():
    ring = SampleRing(2, capacity=5, initial_rows=2)
    for i in range(4):
        ring.add((i, -i))
    assert ring.samples()[:, 0].tolist() == [0, 1, 2, 3]
    for i in range(4, 12):
        ring.add((i, -i))
    assert ring.recorded == 12
    assert ring.samples()[:, 0].tolist() == [7, 8, 9, 10, 11]
    assert ring.samples(since=10)[:, 1].tolist() == [-10, -11]
    assert ring.samples(since=2)[:, 0].tolist() == [7, 8, 9, 10, 11]  # older rows are gone
    assert ring.samples(since=12).shape == (0, 2)


def test_a_ring_rebuilt_from_rows_keeps_them_and_goes_on():
    ring = SampleRing.of(np.arange(6, dtype=np.float32), 2)
    assert ring.recorded == 3 and ring.samples().tolist() == [[0, 1], [2, 3], [4, 5]]
    ring.add((6, 7))  # full: the oldest row goes
    assert ring.samples().tolist() == [[2, 3], [4, 5], [6, 7]]


def test_statistics_rebuilt_from_no_samples_can_record():
    """Was: a ring rebuilt from no rows had no room, and the next frame divided by zero."""
    stats = LatencyStats.from_samples("c", np.zeros((0, 5), np.float32), frames=0, manual=0, malformed=0)
    stats.record((0.001, 0.001, 0.001, 0.001, 0.004))
    assert stats.recorded == 1 and stats.samples().shape == (1, 5)
    tally = MonitorTally.restore(np.zeros((0, 2), np.float32), None)
    assert tally.samples().shape == (0, 2) and tally.frames == 0
