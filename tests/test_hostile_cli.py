"""Where the server listens (issue #10 item 10) and what it counts at run time (item 9, non-finite output)."""

from __future__ import annotations

import base64
import json
import socket

import cv2
import numpy as np
import pytest
from helpers_server import SAMPLE_LOG, build_shallow, run_server_cli
from test_hostile_model import dynamic_mean_graph

from drive_server.serving.contract import PAPER_CONTRACT
from protocol import SteerCommand
from tools.wire.frames import log_frames
from tools.wire.server_process import ServerProcess
from tools.wire.unity_client import UnityWireClient

pytest.importorskip("onnx", reason="the tests build their ONNX models with the onnx package")
pytestmark = pytest.mark.slow

GOOD = log_frames(SAMPLE_LOG)[0].payload()


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return build_shallow(tmp_path_factory.mktemp("hostile_cli") / "m.onnx")


def one_error_line(result) -> str:
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("drive_server: error:"), result.stderr
    return lines[0]


def test_a_second_server_on_a_port_in_use_exits_2(model):
    """Item 10: eventlet's SO_REUSEPORT let a second drive_server share the port silently (replays split 3/2)."""
    with ServerProcess(model, ["--log-every", "0"]) as first:
        port = first.url.rsplit(":", 1)[1]
        line = one_error_line(run_server_cli("--model", str(model), "--port", port))
        assert f"port {port} is already in use" in line
        with UnityWireClient(first.url) as client:  # the first server keeps the port to itself
            assert isinstance(client.exchange(GOOD)[0], SteerCommand)


def test_a_port_bound_with_so_reuseport_by_another_program_is_in_use_too(model):
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert "already in use" in one_error_line(run_server_cli("--model", str(model), "--port", str(port)))


@pytest.mark.parametrize("port", ["70000", "-1", "65536"])
def test_port_out_of_range_is_one_line(model, port):
    """Item 10: --port 70000 or -1 gave a traceback."""
    assert "--port must be in 0..65535" in one_error_line(run_server_cli("--model", str(model), "--port", port))


@pytest.mark.parametrize("args", [["--max-connections", "0"], ["--header-timeout", "0"], ["--max-pending", "1"]])
def test_bad_limits_are_one_line(model, args):
    one_error_line(run_server_cli("--model", str(model), "--port", "0", *args))


@pytest.mark.parametrize("host", ["0.0.0.0", ""])
def test_a_non_local_bind_warns_that_anyone_can_drive_the_car(model, host):
    """Item 10: --host 0.0.0.0 (or "") exposed the server without a word."""
    with ServerProcess(model, ["--log-every", "0", "--host", host]) as srv:
        assert "anyone on the network can drive the car and see its camera" in srv.log()
        port = srv.url.rsplit(":", 1)[1]
        with UnityWireClient(f"http://127.0.0.1:{port}") as client:
            assert isinstance(client.exchange(GOOD)[0], SteerCommand)


def test_localhost_does_not_warn(model):
    with ServerProcess(model, ["--log-every", "0", "--host", "localhost"]) as srv:
        assert "anyone on the network" not in srv.log()


def _ipv6_available() -> bool:
    try:
        with socket.socket(socket.AF_INET6) as s:
            s.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.skipif(not _ipv6_available(), reason="no IPv6 loopback on this machine")
@pytest.mark.parametrize(("host", "warns"), [("::1", False), ("::", True)])
def test_ipv6_works(model, host, warns):
    """Item 10: --host :: failed."""
    with ServerProcess(model, ["--log-every", "0", "--host", host]) as srv:
        assert srv.url.startswith("http://[")
        assert ("anyone on the network" in srv.log()) is warns
        port = srv.url.rsplit(":", 1)[1]
        with UnityWireClient(f"http://[::1]:{port}") as client:
            assert isinstance(client.exchange(GOOD)[0], SteerCommand)


def test_an_unusable_host_is_one_line(model):
    line = one_error_line(run_server_cli("--model", str(model), "--port", "0", "--host", "no-such-host.invalid"))
    assert "no-such-host.invalid" in line


def test_non_finite_model_output_is_counted_as_its_own_kind(tmp_path):
    """Item 9: a NaN output was counted as "malformed input". sqrt(mean(x) + 0.4) is NaN on a black frame only,
    so the model passes the startup check and fails at run time."""
    path = dynamic_mean_graph(tmp_path / "sqrt.onnx", PAPER_CONTRACT.to_json(), sqrt_offset=0.4)
    ok, black = cv2.imencode(".jpg", np.zeros((160, 320, 3), np.uint8))
    stats_path = tmp_path / "stats.json"
    srv = ServerProcess(path, ["--log-every", "0", "--hold-frames", "0"], stats_json=stats_path)
    with srv, UnityWireClient(srv.url) as client:
        good = client.exchange(GOOD)[0]
        assert good != SteerCommand(0.0, -1.0)
        assert client.exchange(dict(GOOD, image=base64.b64encode(black.tobytes()).decode()))[0] == \
            SteerCommand(0.0, -1.0)
        client.exchange(dict(GOOD, speed="abc"))
    total = json.loads(stats_path.read_text())["total"]
    assert (total["frames"], total["bad_output"], total["malformed"]) == (1, 1, 1)
    assert total["bad_input"] == {"number": 1}
    assert "model output (model output is not finite" in srv.log() and "Traceback" not in srv.log()
