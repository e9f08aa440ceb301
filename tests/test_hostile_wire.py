"""Hostile clients on 127.0.0.1 against the REAL drive_server (issue #10, items 1 and 3-8).

Each test reproduces one way a client could stall, starve or exhaust the server, with small limits so
it runs in seconds. Behaviour only: where a test waits, its bound is generous (seconds), never a target.
"""

from __future__ import annotations

import json
import re
import socket
import threading
import time
import urllib.request

import pytest
from helpers_server import SAMPLE_LOG, build_shallow

from protocol import SteerCommand
from tools.wire.frames import log_frames
from tools.wire.server_process import ServerProcess
from tools.wire.unity_client import ConnectionClosed, UnityWireClient
from tools.wire.websocket import client_frame

pytest.importorskip("onnx", reason="the tests build their ONNX model with the onnx package")
pytestmark = pytest.mark.slow

GOOD = log_frames(SAMPLE_LOG)[0].payload()
STOP = SteerCommand(0.0, -1.0)
LIMIT = 256 * 1024


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return build_shallow(tmp_path_factory.mktemp("hostile") / "tiny.onnx", seed=1)


@pytest.fixture(scope="module")
def server(model):
    srv = ServerProcess(model, ["--log-every", "0", "--hold-frames", "0", "--max-pending", "8",
                                "--header-timeout", "2"])
    srv.start()
    yield srv
    assert srv.stop() == 0, srv.log()
    assert "Traceback" not in srv.log(), srv.log()[-3000:]


def host_port(srv: ServerProcess) -> tuple[str, int]:
    host, port = srv.url.removeprefix("http://").rsplit(":", 1)
    return host, int(port)


def close_code(client: UnityWireClient, timeout: float = 10.0) -> int | None:
    """Read until the server closes; the close frame's code (None: closed without a close frame)."""
    with pytest.raises(ConnectionClosed) as info:
        client.receive_reply(timeout)
    match = re.search(r"code (\d+)", str(info.value))
    return int(match.group(1)) if match else None


def wait_for_log(srv: ServerProcess, text: str, timeout: float = 10.0) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if text in srv.log():
            return srv.log()
        time.sleep(0.05)
    raise AssertionError(f"{text!r} not in the server log:\n{srv.log()[-3000:]}")


def polling_session(srv: ServerProcess) -> str:
    with urllib.request.urlopen(f"{srv.url}/socket.io/?EIO=4&transport=polling", timeout=10) as r:
        return json.loads(r.read().decode()[1:])["sid"]


def test_oversized_polling_post_gets_413_and_frees_its_connection(server):
    """Item 1: a POST over the limit (the header alone) was never answered and kept its socket forever."""
    host, port = host_port(server)
    for _ in range(5):
        sid = polling_session(server)
        with socket.create_connection((host, port), timeout=10) as s:
            s.sendall(f"POST /socket.io/?EIO=4&transport=polling&sid={sid} HTTP/1.1\r\nHost: x\r\n"
                      f"Content-Type: text/plain\r\nContent-Length: {10 * LIMIT}\r\n\r\n".encode())
            response = b""
            while chunk := s.recv(4096):  # the server answers AND closes: recv ends
                response += chunk
        assert response.startswith(b"HTTP/1.1 413"), response
    with UnityWireClient(server.url) as client:
        assert isinstance(client.exchange(GOOD)[0], SteerCommand)


def test_polling_post_with_garbage_is_refused_without_a_traceback(server):
    sid = polling_session(server)
    req = urllib.request.Request(f"{server.url}/socket.io/?EIO=4&transport=polling&sid={sid}", data=b"hello",
                                 method="POST")
    with pytest.raises(urllib.error.HTTPError) as info:
        urllib.request.urlopen(req, timeout=10)
    assert info.value.code == 400


def test_continuation_frames_cannot_bypass_the_message_limit(server):
    """Item 3: 200 KiB fragments of one text message were buffered whole (256 MiB -> +513 MiB RSS)."""
    with UnityWireClient(server.url) as client:
        client.socket.sendall(client_frame(0x1, b'42["telemetry",{"image":"' + b"A" * 200_000, fin=False))
        client.socket.sendall(client_frame(0x0, b"A" * 200_000, fin=False))  # 400 KB so far, still not final
        assert close_code(client) == 1009  # closed while the message arrives, not after it is complete
    with UnityWireClient(server.url) as client:
        assert isinstance(client.exchange(GOOD)[0], SteerCommand)


def test_a_client_that_does_not_read_is_dropped_and_starves_nobody(server):
    """Item 4: one client writing telemetries without reading its replies held every other client for seconds."""
    flood = UnityWireClient(server.url)
    flood.connect()
    flood.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    frames = flood.telemetry_frame(None) * 10_000  # manual-mode telemetries, ~300 KB a batch
    sent = threading.Event()

    def write_forever():  # until the server closes the connection
        try:
            while True:
                flood.socket.sendall(frames)
        except OSError:
            pass
        sent.set()

    writer = threading.Thread(target=write_forever, daemon=True)
    writer.start()
    try:
        with UnityWireClient(server.url) as healthy:
            for _ in range(20):
                reply, round_trip = healthy.exchange(GOOD)
                assert isinstance(reply, SteerCommand)
                assert round_trip < 2.0, f"a healthy client waited {round_trip:.1f} s behind a flooding one"
        log = wait_for_log(server, "does not read its replies")
        assert sent.wait(30), "the server never closed the connection of the client that does not read"
    finally:
        flood.close()
    assert log.count("does not read its replies") == 1


def test_every_telemetry_is_answered_however_it_is_written(server):
    """Item 5: a payload nested 2,000 deep and a 400-digit JSON speed were never answered."""
    with UnityWireClient(server.url) as client:
        client.send_text('42["telemetry",' + "[" * 2000 + "]" * 2000 + "]")
        assert client.receive_reply(10) == STOP
        client.send_text('42["telemetry",' + json.dumps(dict(GOOD, speed=None))[:-1].replace("null", "1" * 400)
                         + "}]")
        assert client.receive_reply(10) == STOP
        client.send_text('42["telemetry",{"speed": 1' + "0" * 5000 + "}]")  # python's int() refuses 4,300+ digits
        assert client.receive_reply(10) == STOP
        client.send_text('42["telemetry",{"speed":"1"')  # invalid JSON
        assert client.receive_reply(10) == STOP
        client.send_text('421["telemetry",' + json.dumps(dict(GOOD, speed="-1e308")) + "]")  # with an ack id
        assert client.receive_reply(10) == STOP
        assert isinstance(client.exchange(GOOD)[0], SteerCommand) and client.exchange(GOOD)[0] != STOP


@pytest.mark.parametrize("packet", ["45", "46", "451-[\"telemetry\",{}]", "4[[[[]]]]", "44{}"])
def test_binary_or_bogus_socketio_packets_close_only_that_connection(server, packet):
    """Item 5: after "45" or "46" no telemetry on the connection was ever answered again."""
    with UnityWireClient(server.url) as bystander, UnityWireClient(server.url) as client:
        assert isinstance(client.exchange(GOOD)[0], SteerCommand)
        client.send_text(packet)
        client.send_telemetry(GOOD)
        assert close_code(client) == 1002  # a close frame, not a silent stall
        assert isinstance(bystander.exchange(GOOD)[0], SteerCommand)


def test_garbage_floods_write_a_few_lines_not_thousands(server):
    """Item 6: after one "46", 2,000 small messages wrote 4,000 tracebacks (3 MB)."""
    before = server.log()
    for _ in range(30):
        with UnityWireClient(server.url) as client:
            client.send_text("46")
            for _ in range(50):
                try:
                    client.send_text("x")
                except ConnectionClosed:
                    break
            close_code(client)
    with UnityWireClient(server.url) as client:
        for _ in range(200):
            client.exchange(dict(GOOD, image="!!"))
    new = server.log()[len(before):]
    assert "Traceback" not in new
    assert new.count("protocol error") <= 3 and new.count("malformed frame") <= 3, new
    assert len(new) < 20_000, f"{len(new)} bytes of log for 1,700 bad messages"


@pytest.mark.parametrize("text", ["hello", ""])
def test_garbage_text_gets_a_close_frame_and_the_session_ends(server, text):
    """Item 7: "hello" or an empty frame got an HTTP 500 written into the WebSocket stream, and the session
    lingered about 60 s as a connected client."""
    with UnityWireClient(server.url) as client:
        client.exchange(GOOD)
        client.send_text(text)
        assert close_code(client) == 1002
    wait_for_log(server, "disconnected (transport close)", timeout=5)


@pytest.fixture
def small_server(model, request):
    srv = ServerProcess(model, ["--log-every", "0", *request.param])
    srv.start()
    yield srv
    assert srv.stop() == 0, srv.log()
    assert "Traceback" not in srv.log(), srv.log()[-3000:]


@pytest.mark.parametrize("small_server", [["--max-connections", "4", "--header-timeout", "60"]], indirect=True)
def test_half_open_connections_cannot_keep_clients_out(small_server):
    """Item 8: ~1,074 half-open HTTP connections (no header timeout) kept every new client out."""
    host, port = host_port(small_server)
    half_open = [socket.create_connection((host, port), timeout=10) for _ in range(8)]
    try:
        for s in half_open[:4]:
            s.sendall(b"GET /socket.io/?EIO=4 HTTP/1.1\r\n")  # and never the rest of the headers
        time.sleep(0.3)
        with UnityWireClient(small_server.url) as client:  # admitted by closing the oldest half-open one
            assert isinstance(client.exchange(GOOD)[0], SteerCommand)
        wait_for_log(small_server, "connection limit (4) reached: closed the oldest connection")
    finally:
        for s in half_open:
            s.close()


@pytest.mark.parametrize("small_server", [["--max-connections", "3", "--idle-evict", "1"]], indirect=True)
def test_idle_websockets_give_their_slots_to_a_new_simulator(small_server):
    """Issue 25: an upgraded WebSocket that sends nothing held its slot until the ping timeout (45 s),
    so a burst of idle sockets kept every new simulator out (503) although none of them was driving."""
    idle = [UnityWireClient(small_server.url) for _ in range(3)]
    try:
        for c in idle:
            c.connect()  # upgraded, and then silent
        with pytest.raises(ConnectionError, match="503"):  # not silent long enough yet: refused
            UnityWireClient(small_server.url).connect()
        time.sleep(1.3)
        with UnityWireClient(small_server.url) as newcomer:  # the idlest gives way
            assert isinstance(newcomer.exchange(GOOD)[0], SteerCommand)
            wait_for_log(small_server, "closed a WebSocket silent for 1 s (--idle-evict)")
            close_code(idle[0], timeout=5)  # the first to fall silent is the one closed (raises if open)
            assert isinstance(newcomer.exchange(GOOD)[0], SteerCommand)
    finally:
        for c in idle:
            c.close()


@pytest.mark.parametrize("small_server", [["--max-connections", "2", "--idle-evict", "1"]], indirect=True)
def test_a_websocket_that_keeps_driving_is_never_evicted(small_server):
    with UnityWireClient(small_server.url) as a, UnityWireClient(small_server.url) as b:
        for _ in range(8):  # both drive for 1.6 s, past the idle limit
            assert isinstance(a.exchange(GOOD)[0], SteerCommand) and isinstance(b.exchange(GOOD)[0], SteerCommand)
            time.sleep(0.2)
        with pytest.raises(ConnectionError, match="503"):
            UnityWireClient(small_server.url).connect()
        assert isinstance(a.exchange(GOOD)[0], SteerCommand) and isinstance(b.exchange(GOOD)[0], SteerCommand)


@pytest.mark.parametrize("small_server", [["--max-connections", "8", "--header-timeout", "1"]], indirect=True)
def test_a_connection_that_sends_no_headers_is_closed_after_the_header_timeout(small_server):
    host, port = host_port(small_server)
    with socket.create_connection((host, port), timeout=10) as s:
        s.sendall(b"GET /socket.io/?EIO=4&transport=websocket HTTP/1.1\r\nHost: x\r\n")  # no blank line, ever
        assert s.recv(100) == b""  # closed by the server (after ~1 s)
    wait_for_log(small_server, "no complete request within 1 s")


@pytest.mark.parametrize("small_server", [["--max-connections", "2"]], indirect=True)
def test_connection_limit_refuses_with_503_and_one_log_line(small_server):
    with UnityWireClient(small_server.url) as a, UnityWireClient(small_server.url) as b:
        for _ in range(3):
            with pytest.raises(ConnectionError, match="503"):
                UnityWireClient(small_server.url).connect()
        assert isinstance(a.exchange(GOOD)[0], SteerCommand) and isinstance(b.exchange(GOOD)[0], SteerCommand)
    time.sleep(0.3)
    with UnityWireClient(small_server.url) as c:  # a slot is free again
        assert isinstance(c.exchange(GOOD)[0], SteerCommand)
    assert small_server.log().count("connection limit (2, --max-connections) reached") == 1


@pytest.mark.parametrize("small_server", [["--max-connections", "8"]], indirect=True)
def test_a_client_reconnecting_in_a_loop_cannot_flood_the_log(small_server):
    """Every connect and disconnect wrote a line: a reconnect loop was a log flood at INFO."""
    for _ in range(60):
        with UnityWireClient(small_server.url) as c:
            assert isinstance(c.exchange(GOOD)[0], SteerCommand)
    with UnityWireClient(small_server.url) as c:  # the server still answers
        assert isinstance(c.exchange(GOOD)[0], SteerCommand)
    time.sleep(0.5)
    text = small_server.log()
    assert 20 <= text.count(" connected from ") <= 40  # 20 per 10 s, the rest counted
    assert 20 <= text.count(" disconnected (") <= 40
