"""End to end: the REAL drive_server process with a tiny ONNX model, driven by the Unity-wire client,
python-socketio 5 and (if installed) socket.io-client 4 under Node.js. Behaviour only, never timing."""

from __future__ import annotations

import base64
import json
import queue
import shutil
import subprocess
import time

import pytest
from helpers_server import REPO, SAMPLE_LOG, build_shallow, jpeg_b64

from protocol import SteerCommand, parse_steer
from tools.wire.frames import log_frames
from tools.wire.server_process import ServerProcess
from tools.wire.unity_client import ConnectionClosed, UnityWireClient

pytest.importorskip("onnx", reason="the tests build their ONNX model with the onnx package")
pytestmark = pytest.mark.slow

FRAMES = log_frames(SAMPLE_LOG)
GOOD = FRAMES[0].payload()
STOP = SteerCommand(0.0, -1.0)
HOLD = 3


def malformed_payloads() -> list:
    """One of every kind of bad frame the server must answer without crashing."""
    return [
        dict(GOOD, image="!!!not base64!!!"),
        dict(GOOD, image=base64.b64encode(b"GIF89a" + bytes(64)).decode()),
        dict(GOOD, image=jpeg_b64(100, 50)),
        dict(GOOD, speed="NaN"),
        dict(GOOD, speed="abc"),
        {k: v for k, v in GOOD.items() if k != "image"},
        {"steering_angle": "0"},
        [1, 2, 3],
    ]


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return build_shallow(tmp_path_factory.mktemp("model") / "tiny.onnx", seed=1)


@pytest.fixture(scope="module")
def server(model):
    srv = ServerProcess(model, ["--log-every", "0", "--hold-frames", str(HOLD), "--ping-interval", "1"])
    srv.start()
    yield srv
    assert srv.stop() == 0, srv.log()
    assert "Traceback" not in srv.log(), srv.log()


def test_unity_client_two_telemetries_at_open_and_no_connect_packet(server):
    with UnityWireClient(server.url) as client:
        client.open_burst(GOOD)
        deadline = time.monotonic() + 10
        packets = [client._receive_packet(deadline), client._receive_packet(deadline)]
    # joined to '/' silently: the first packets it sees are the two replies, not a CONNECT ('40')
    assert all(p.startswith('42["steer",') for p in packets), packets
    first, second = (parse_steer(json.loads(p[2:])[1]) for p in packets)
    assert first == second and -1.0 <= first.steering <= 1.0 and -1.0 <= first.throttle <= 1.0


def test_reply_values_are_strings_with_a_dot(server):
    with UnityWireClient(server.url) as client:
        client.send_telemetry(dict(GOOD, speed="3,5"))
        packet = client._receive_packet(time.monotonic() + 10)
    payload = json.loads(packet[2:])[1]
    assert set(payload) == {"steering_angle", "throttle"}
    assert all(isinstance(v, str) and "," not in v and "." in v for v in payload.values())


def test_null_frames_get_manual(server):
    with UnityWireClient(server.url) as client:
        assert client.exchange(None)[0] is None
        assert isinstance(client.exchange(GOOD)[0], SteerCommand)
        assert client.exchange(None)[0] is None


def test_comma_locale_gives_the_same_command(server):
    with UnityWireClient(server.url) as dot, UnityWireClient(server.url, decimal=",") as comma:
        for frame in FRAMES[:3]:
            assert dot.exchange(frame.payload())[0] == comma.exchange(frame.payload())[0]


def test_pings_both_ways(server):
    with UnityWireClient(server.url) as client:
        client.ping_interval_s = 0.0  # the simulator's own ping '2' before every frame
        client.exchange(GOOD)
        time.sleep(1.3)  # the server pings every second: answered with '3' while reading the next reply
        for _ in range(3):
            assert isinstance(client.exchange(GOOD)[0], SteerCommand)
        assert client.pings_sent >= 3 and client.pings_answered >= 1


def test_malformed_frames_mid_stream_hold_then_stop(server):
    with UnityWireClient(server.url) as client:
        good = client.exchange(GOOD)[0]
        replies = [client.exchange(p)[0] for p in malformed_payloads()]
        assert replies[:HOLD] == [good] * HOLD
        assert replies[HOLD:] == [STOP] * (len(replies) - HOLD)
        client.send_text('42["telemetry",{"speed":"1"},"extra"]')  # extra arguments: answered too
        assert client.receive_reply(10) == STOP
        client.send_text('42["telemetry"]')  # no payload (python-socketio's emit(event, None)): manual
        assert client.receive_reply(10) is None
        assert client.exchange(GOOD)[0] == good  # recovers on the next good frame
        assert client.exchange(dict(GOOD, speed="abc"))[0] == good  # and holds again


def test_two_unity_clients_each_get_only_their_own_replies(server):
    with UnityWireClient(server.url) as a, UnityWireClient(server.url) as b:
        a_good = a.exchange(GOOD)[0]
        a.send_telemetry(GOOD)
        b.send_telemetry(None)
        assert b.receive_reply(10) is None and a.receive_reply(10) == a_good
        for _ in range(HOLD + 1):  # b runs out of held commands ...
            assert b.exchange(dict(GOOD, image="x"))[0] == STOP  # (b never had a good frame)
        assert a.exchange(dict(GOOD, image="x"))[0] == a_good  # ... a still holds its own
        with pytest.raises(TimeoutError):
            b.receive_reply(0.3)  # nothing extra arrived for b


def test_oversized_message_is_refused_and_the_server_lives_on(server):
    with UnityWireClient(server.url) as client:
        client.send_telemetry(dict(GOOD, image="A" * 400_000))
        with pytest.raises((ConnectionClosed, ConnectionError)):
            client.receive_reply(10)
    with UnityWireClient(server.url) as client:
        assert isinstance(client.exchange(GOOD)[0], SteerCommand)


@pytest.mark.parametrize("transports", [["websocket"], ["polling", "websocket"]])
def test_python_socketio_client(server, transports):
    socketio = pytest.importorskip("socketio")
    replies: queue.Queue = queue.Queue()
    sio = socketio.Client(reconnection=False)
    sio.on("steer", lambda data: replies.put(("steer", data)))
    sio.on("manual", lambda data: replies.put(("manual", data)))
    sio.connect(server.url, transports=transports, wait_timeout=10)
    try:
        sent = [GOOD, None, malformed_payloads()[0], FRAMES[1].payload()]
        got = []
        for payload in sent:  # closed loop, like the simulator
            sio.emit("telemetry", payload)
            got.append(replies.get(timeout=10))
        assert [e for e, _ in got] == ["steer", "manual", "steer", "steer"]
        assert got[1][1] == {}
        assert parse_steer(got[2][1]) == parse_steer(got[0][1])  # malformed: held
        assert replies.empty()
    finally:
        sio.disconnect()


def test_python_socketio_and_unity_clients_at_once(server):
    socketio = pytest.importorskip("socketio")
    replies: queue.Queue = queue.Queue()
    sio = socketio.Client(reconnection=False)
    sio.on("steer", lambda data: replies.put(data))
    sio.connect(server.url, transports=["websocket"], wait_timeout=10)
    try:
        with UnityWireClient(server.url) as unity:
            for frame in FRAMES[:5]:
                sio.emit("telemetry", frame.payload())
                unity.send_telemetry(frame.payload())
                assert parse_steer(replies.get(timeout=10)) == unity.receive_reply(10)
            time.sleep(0.2)
            assert replies.empty()
    finally:
        sio.disconnect()


def _node_client() -> str:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed")
    if not (REPO / "tests" / "js" / "node_modules" / "socket.io-client").is_dir():
        pytest.skip("socket.io-client is not installed: npm install --prefix tests/js socket.io-client@4")
    return node


def test_socketio_client_4_under_node(server, tmp_path):
    node = _node_client()
    sent = [GOOD, None, *malformed_payloads()[:HOLD + 1], FRAMES[2].payload()]
    payloads = tmp_path / "payloads.json"
    payloads.write_text(json.dumps(sent))
    out = subprocess.run([node, str(REPO / "tests" / "js" / "drive_client.js"), server.url, str(payloads)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    lines = [json.loads(line) for line in out.stdout.splitlines()]
    assert lines[-1] == {"done": True}
    events = lines[:-1]
    assert [e["event"] for e in events] == ["steer", "manual"] + ["steer"] * (HOLD + 2)
    good = parse_steer(events[0]["data"])
    assert events[1]["data"] == {}
    assert [parse_steer(e["data"]) for e in events[2:2 + HOLD]] == [good] * HOLD
    assert parse_steer(events[2 + HOLD]["data"]) == STOP


def test_node_and_unity_clients_at_once(server, tmp_path):
    """The issue's acceptance: a JavaScript socket.io client and a Unity-wire client steered side by side."""
    node = _node_client()
    payloads = tmp_path / "payloads.json"
    payloads.write_text(json.dumps([f.payload() for f in FRAMES[:30]]))
    js = subprocess.Popen([node, str(REPO / "tests" / "js" / "drive_client.js"), server.url, str(payloads)],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        with UnityWireClient(server.url) as unity:
            for frame in FRAMES[:30]:  # interleaved with the JS client's closed loop
                command, _ = unity.exchange(frame.payload())
                assert command is not None
        out, err = js.communicate(timeout=60)
    finally:
        js.kill()
    assert js.returncode == 0, err
    events = [json.loads(line) for line in out.splitlines()]
    assert events[-1] == {"done": True}
    assert [e["event"] for e in events[:-1]] == ["steer"] * 30  # exactly one reply per telemetry, its own


def test_stats_json_written_at_exit(model, tmp_path):
    stats_path = tmp_path / "stats.json"
    srv = ServerProcess(model, ["--log-every", "0.3"], stats_json=stats_path)
    with srv, UnityWireClient(srv.url) as client:
        for frame in FRAMES[:5]:
            client.exchange(frame.payload())
        client.exchange(None)
        client.exchange(dict(GOOD, speed="abc"))
        client.exchange(dict(GOOD, image="x"))
        time.sleep(0.8)  # at least one periodic summary line
    assert srv.returncode == 0
    stats = json.loads(stats_path.read_text())
    total = stats["total"]
    assert (total["frames"], total["manual"], total["malformed"]) == (5, 1, 2)
    assert set(total["stages_ms"]) == {"decode", "preprocess", "inference", "control", "total"}
    assert stats["contract_source"] == "metadata" and stats["transport"]["fast_unmask"] is True
    assert len(stats["clients"]) == 1
    assert "malformed frame" in srv.log()  # the rate-limited warning
    assert "1 client(s): frames 5 manual 1 malformed 2 | p50/p99 ms decode" in srv.log()


def test_worker_processes_share_the_port(model, tmp_path):
    socketio = pytest.importorskip("socketio")
    stats_path = tmp_path / "stats.json"
    srv = ServerProcess(model, ["--log-every", "0", "--workers", "2"], stats_json=stats_path)
    with srv:
        clients = [UnityWireClient(srv.url) for _ in range(4)]
        for c in clients:
            c.connect()
        for frame in FRAMES[:3]:
            for c in clients:
                assert isinstance(c.exchange(frame.payload())[0], SteerCommand)
        assert clients[0].exchange(dict(GOOD, image="x"))[0] == clients[0].exchange(FRAMES[2].payload())[0]
        for c in clients:
            c.close()
        replies: queue.Queue = queue.Queue()
        sio = socketio.Client(reconnection=False)
        sio.on("manual", lambda data: replies.put(data))
        sio.connect(srv.url, transports=["websocket"], wait_timeout=10)
        sio.emit("telemetry", None)
        assert replies.get(timeout=10) == {}
        sio.disconnect()
    assert srv.returncode == 0, srv.log()
    assert "2 worker processes" in srv.log() and "[w0]" in srv.log() and "[w1]" in srv.log()
    stats = json.loads(stats_path.read_text())
    assert stats["workers"] == 2
    assert (stats["total"]["frames"], stats["total"]["malformed"], stats["total"]["manual"]) == (13, 1, 1)
    assert len(stats["clients"]) == 5


def test_a_live_view_viewer_that_leaves_gives_its_file_descriptor_back(model):
    """Found by rbc soak: a viewer gone (EPIPE) left its socket in a reference cycle, and a quiet server kept
    its fd open until the next telemetry ran the garbage collector."""
    import os
    import socket

    with ServerProcess(model, ["--log-every", "0", "--dashboard"]) as srv:
        fds = lambda: len(os.listdir(f"/proc/{srv.pid}/fd"))  # noqa: E731
        with UnityWireClient(srv.url) as c:  # the server as after a drive: warmed up, then quiet
            c.exchange(GOOD)
        time.sleep(0.5)
        before = fds()
        host, port = srv.url.removeprefix("http://").split(":")
        for _ in range(3):
            viewer = socket.create_connection((host, int(port)), timeout=10)
            viewer.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
            assert viewer.recv(64).startswith(b"HTTP/1.1 200")
            viewer.close()
        deadline = time.monotonic() + 8
        while fds() > before and time.monotonic() < deadline:
            time.sleep(0.2)
        assert fds() == before
