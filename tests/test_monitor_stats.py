"""What the server reports of a client's monitor: frames and episodes per state, switch-offs counted once, the score
and time percentiles, through a worker's hand-back, in the log line, ``--stats-json`` and ``rbc bench``'s table."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import pytest
from helpers_server import build_shallow
from test_monitor import FRAMES, _brightness_graph, _with_monitor

from drive_server.observing.monitor_stats import MonitorTally
from drive_server.observing.stats import LatencyStats, load_stats, save_stats, summarize, summary_line
from drive_server.serving.client_monitor import MonitorReading, MonitorState
from drive_server.serving.monitor import MonitorSpec

SPEC = MonitorSpec("scripted", 0.5, 0.8, 1)


@dataclass
class _Scripted:
    """What the tally reads of a ClientMonitor: the last reading, why it failed, its time."""

    state: MonitorState
    last: MonitorReading | None = None
    failed: str | None = None
    seconds: float = 0.002


def _tally(scores: list[float]) -> tuple[MonitorTally, MonitorState]:
    tally, monitor = MonitorTally(1000), _Scripted(MonitorState(SPEC))
    for s in scores:
        monitor.last = monitor.state.update(s)
        tally.note(monitor)  # type: ignore[arg-type]
    return tally, monitor.state


def test_frames_and_episodes_per_state_follow_the_state_machine():
    # warning, alarm (from warning: one alarm episode), 15 calm frames hand back, then a second warning
    scores = [0.0, 0.6, 0.6, 0.9, 0.1] + [0.1] * 15 + [0.6]
    tally, state = _tally(scores)
    assert tally.states == state.counts and tally.frames == len(scores)
    assert tally.episodes == state.episodes == {"warning": 2, "alarm": 1}
    out = summarize([_with(tally)])["monitor"]
    assert out["score"]["max"] == pytest.approx(0.9) and out["time_ms"]["p50"] == pytest.approx(2.0)


def _with(tally: MonitorTally) -> LatencyStats:
    stats = LatencyStats("c")
    stats.monitor = tally
    return stats


def test_a_monitor_switched_off_is_counted_once_and_scores_no_more_frames():
    tally, monitor = MonitorTally(10), _Scripted(MonitorState(SPEC))
    monitor.last = monitor.state.update(0.1)
    tally.note(monitor)  # type: ignore[arg-type]
    monitor.failed, monitor.last = "RuntimeError: boom", None
    for _ in range(5):
        tally.note(monitor)  # type: ignore[arg-type]
    assert (tally.frames, tally.switched_off) == (1, 1)
    line = summary_line(summarize([_with(tally)]))
    assert "monitor: warning 0 alarm 0 of 1 frames" in line and "switched off for 1 client(s)" in line


def test_without_a_monitor_the_summary_and_line_say_nothing_of_one():
    stats = LatencyStats("a")
    stats.record((0.001,) * 5)
    assert "monitor" not in summarize([stats]) and "monitor" not in summary_line(summarize([stats]))


def test_a_workers_hand_back_keeps_the_monitor_figures(tmp_path):
    a, b = _with(_tally([0.0, 0.9, 0.9])[0]), LatencyStats("b")
    a.record((0.001,) * 5)
    save_stats(tmp_path / "w.npz", [a, b])
    back = load_stats(tmp_path / "w.npz")
    assert summarize(back) == summarize([a, b])
    assert summarize(back)["monitor"]["episodes"] == {"warning": 0, "alarm": 1}
    old = LatencyStats("old", capacity=1)  # a client too old to keep one by one: its counters survive
    old.absorb_counters(a)
    assert old.monitor.states == a.monitor.states


@pytest.mark.slow
def test_the_stats_json_and_rbc_bench_report_the_monitor(tmp_path):
    """The real server, act, every frame alarming: ``--stats-json`` counts the frames per state and the single alarm
    episode, and the benchmark's table prints the monitor's time and line."""
    from tools.bench.latency import BenchResult, format_table
    from tools.wire.server_process import ServerProcess
    from tools.wire.unity_client import UnityWireClient

    plain = build_shallow(tmp_path / "plain.onnx", seed=1)
    alarming = _with_monitor(plain, tmp_path / "alarming.onnx", MonitorSpec("brightness", -0.5, -0.2, 3),
                             _brightness_graph())
    stats_path = tmp_path / "stats.json"
    srv = ServerProcess(alarming, ["--log-every", "0", "--monitor", "act"], stats_json=stats_path)
    srv.start()
    try:
        with UnityWireClient(srv.url) as client:
            for frame in FRAMES[:6]:
                client.exchange(frame.payload())
    finally:
        assert srv.stop() == 0, srv.log()
    deadline = time.monotonic() + 10
    while not stats_path.is_file() and time.monotonic() < deadline:
        time.sleep(0.05)
    doc = json.loads(stats_path.read_text())
    monitor = doc["total"]["monitor"]
    assert monitor["states"] == {"normal": 0, "warning": 0, "alarm": 6}
    assert monitor["episodes"] == {"warning": 0, "alarm": 1} and monitor["switched_off"] == 0
    assert doc["clients"][0]["monitor"]["frames"] == 6
    assert "monitor: warning 0 alarm 6 of 6 frames" in srv.log()  # the line logged on stopping
    table = format_table(BenchResult("m", str(alarming), 1, 6, 0, {"p50": 1.0, "p90": 1.0, "p99": 1.0, "max": 1.0},
                                     100.0, doc))
    assert "  of which monitor" in table and "(0 warning, 1 alarm episodes)" in table
