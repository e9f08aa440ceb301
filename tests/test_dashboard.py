"""The live view's server side without a browser: routes, read-only, bounded viewers, slow viewers dropped."""

from __future__ import annotations

import json
import queue

from drive_server.observing.dashboard import Dashboard, DashboardConfig


class _Queue(queue.Queue):
    """The stdlib queue stands in for eventlet's LightQueue (same put_nowait/get_nowait/full/get)."""


def _dashboard(snapshots: list[bool] | None = None, **config) -> tuple[Dashboard, list]:
    spawned = []
    calls = snapshots if snapshots is not None else []

    def snapshot(with_latency: bool) -> dict:
        calls.append(with_latency)
        return {"server": {"viewers": 0}, "clients": []}

    d = Dashboard(snapshot, sleep=lambda s: None, spawn=lambda fn: spawned.append(fn),
                  make_queue=lambda n: _Queue(n), config=DashboardConfig(**config))
    return d, spawned


def _get(d: Dashboard, path: str, method: str = "GET") -> tuple[str, dict, object]:
    seen = {}

    def start_response(status, headers):
        seen["status"], seen["headers"] = status, dict(headers)

    body = d.wsgi({"PATH_INFO": path, "REQUEST_METHOD": method}, start_response)
    return seen["status"], seen["headers"], body


def test_the_page_and_its_files_are_served_and_nothing_else():
    d, _ = _dashboard()
    status, headers, body = _get(d, "/")
    assert status == "200 OK" and headers["Content-Type"].startswith("text/html") and b"EventSource" not in body[0]
    assert b"/dashboard.js" in body[0]
    assert _get(d, "/dashboard.js")[1]["Content-Type"].startswith("text/javascript")
    assert _get(d, "/dashboard.css")[1]["Content-Type"].startswith("text/css")
    assert _get(d, "/nope")[0].startswith("404")
    for method in ("POST", "PUT", "DELETE", "PATCH"):
        assert _get(d, "/", method)[0].startswith("405")


def test_a_viewer_that_does_not_read_is_dropped_never_waited_for():
    d, spawned = _dashboard(queue=2)
    status, headers, stream = _get(d, "/events")
    assert status == "200 OK" and headers["Content-Type"] == "text/event-stream"
    assert next(stream) == b"retry: 1000\n\n"  # connected
    assert d.viewers == 1 and len(spawned) == 1
    ticks = 0

    def sleep(_):
        nonlocal ticks
        ticks += 1

    d._sleep = sleep
    spawned[0]()  # the ticker: the stream is never read, so its queue fills, and it is dropped
    assert d.viewers == 0 and d.dropped == 1 and ticks <= 3


def test_viewers_read_snapshots_and_latency_comes_at_its_own_rate():
    calls: list[bool] = []
    d, spawned = _dashboard(calls, rate_hz=10, stats_hz=2, queue=64)
    _, _, stream = _get(d, "/events")
    next(stream)
    n = 0

    def sleep(_):
        nonlocal n
        n += 1
        if n == 10:
            d._forget(d._viewers[0])  # the viewer goes away after 10 ticks

    d._sleep = sleep
    spawned[0]()
    assert len(calls) == 10 and calls.count(True) == 2  # 10 snapshots, percentiles in 2 of them
    message = next(stream)
    assert message.startswith(b"data: ") and json.loads(message[6:]) == {"server": {"viewers": 0}, "clients": []}


def test_the_number_of_viewers_is_bounded():
    d, _ = _dashboard(max_viewers=2)
    assert _get(d, "/events")[0] == "200 OK" and _get(d, "/events")[0] == "200 OK"
    assert _get(d, "/events")[0].startswith("503")


def test_the_watch_pacer_keeps_simulated_time_at_the_wall_clocks_pace():
    from types import SimpleNamespace

    from tools.sim.driving.pacing import WallClockPacer

    wall = [100.0]
    slept: list[float] = []

    def sleep(s: float) -> None:
        slept.append(s)
        wall[0] += s

    pacer = WallClockPacer(clock=lambda: wall[0], sleep=sleep)
    for k in range(31):  # two seconds of 15 Hz frames, computed instantly
        pacer(SimpleNamespace(t=k / 15))
    assert abs(wall[0] - 102.0) < 1e-9 and len(slept) == 30
