"""Latency statistics: ring buffer, percentiles, summary line, saved samples."""

from __future__ import annotations

import numpy as np

from drive_server.observing.stats import (
    STAGES,
    LatencyStats,
    load_stats,
    save_stats,
    summarize,
    summary_line,
)


def test_percentiles_per_stage_in_ms():
    s = LatencyStats("a")
    for i in range(1, 101):
        s.record(tuple(i * 1e-3 * (k + 1) for k in range(len(STAGES))))
    out = s.summary()
    assert out["frames"] == 100 and out["sampled"] == 100
    assert out["stages_ms"]["decode"]["p50"] == np.percentile(np.arange(1, 101), 50)
    assert out["stages_ms"]["total"]["max"] == 500.0


def test_ring_keeps_memory_bounded():
    s = LatencyStats(capacity=3000)
    for i in range(5000):
        s.record((i,) * 5)
    assert s.frames == 5000 and len(s.samples()) == 3000
    np.testing.assert_array_equal(s.samples()[:, 0], np.arange(2000, 5000))  # oldest first
    np.testing.assert_array_equal(s.samples(since=4990)[:, 0], np.arange(4990, 5000))
    assert len(s.samples(since=6000)) == 0


def test_counters_without_timings_add_no_samples():
    s = LatencyStats(capacity=1)
    s.frames, s.malformed = 10, 2
    assert len(s.samples()) == 0 and summarize([s])["frames"] == 10


def test_summary_of_several_clients_and_counters():
    a, b = LatencyStats("a"), LatencyStats("b")
    a.record((0.001,) * 5)
    b.malformed, b.manual = 3, 2
    out = summarize([a, b])
    assert (out["frames"], out["malformed"], out["manual"]) == (1, 3, 2)
    line = summary_line(out)
    assert "frames 1" in line and "malformed 3" in line and "total 1.000/1.000" in line
    assert summary_line(summarize([])) == "frames 0 manual 0 malformed 0"


def test_save_and_load_round_trip(tmp_path):
    a, b = LatencyStats("a"), LatencyStats("b")
    for i in range(10):
        a.record((i * 1e-3,) * 5)
    b.manual = 4
    save_stats(tmp_path / "w.npz", [a, b])
    back = load_stats(tmp_path / "w.npz")
    assert [s.name for s in back] == ["a", "b"] and back[1].manual == 4
    assert summarize(back) == summarize([a, b])
