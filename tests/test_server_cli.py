"""The drive_server command line: bad models and bad options end with exit code 2 and ONE line; imports stay
within the deployment packages."""

from __future__ import annotations

import subprocess
import sys

import pytest
from helpers_server import REPO, build_graph, build_shallow, run_server_cli

from drive_server.serving.models_dir import default_model_path

pytest.importorskip("onnx", reason="the tests build their ONNX models with the onnx package")
from onnx import helper  # noqa: E402

pytestmark = pytest.mark.slow


def assert_one_line_error(result, *words):
    assert result.returncode == 2, result.stderr
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("drive_server: error:")
    for word in words:
        assert word in lines[0], lines[0]
    assert "listening" not in result.stdout + result.stderr


def relu_graph(path, in_shape, outputs=1):
    """Output(s) the size of the input: an image, not a steering value."""
    outs = [(f"y{i}", in_shape) for i in range(outputs)]
    nodes = [helper.make_node("Relu", ["x"], [f"y{i}"]) for i in range(outputs)]
    return build_graph(path, [("x", in_shape)], outs, nodes)


def mean_graph(path, in_shape):
    """One value out (the mean of the input), whatever the input shape."""
    out_shape = [1] * len(in_shape)
    return build_graph(path, [("x", in_shape)], [("y", out_shape)], [helper.make_node("ReduceMean", ["x"], ["y"])])


def bad_models(tmp_path):
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"this is not a protobuf at all \x00\x01\x02")
    return {
        "missing": (tmp_path / "nope.onnx", "not found"),
        "not onnx": (junk, "cannot load"),
        "rank 3": (mean_graph(tmp_path / "rank3.onnx", [1, 64, 64]), "rank 4"),
        "4 channels": (mean_graph(tmp_path / "c4.onnx", [1, 64, 64, 4]), "3-channel"),
        "two outputs": (relu_graph(tmp_path / "two.onnx", [1, 64, 64, 3], outputs=2), "one output"),
        "image output": (relu_graph(tmp_path / "img.onnx", [1, 64, 64, 3]), "one steering value"),
    }


def test_bad_model_files_exit_2_with_one_line(tmp_path):
    for name, (path, words) in bad_models(tmp_path).items():
        result = run_server_cli("--model", str(path), "--port", "0")
        assert_one_line_error(result, words)
        assert str(path.name) in result.stderr, name


@pytest.mark.parametrize(("args", "words"), [
    (["--tau", "1.5"], "tau"),
    (["--speed-limit", "0"], "speed limit"),
    (["--speed-limit", "nan"], "speed limit"),
    (["--threads", "0"], "threads"),
    (["--provider", "NoSuchExecutionProvider"], "not available"),
    (["--workers", "0"], "--workers"),
    (["--ping-interval", "0.5"], "--ping-interval"),
])
def test_bad_options_exit_2(tmp_path, args, words):
    model = build_shallow(tmp_path / "m.onnx")
    assert_one_line_error(run_server_cli("--model", str(model), "--port", "0", *args), words)


def test_missing_default_model_is_a_clear_error(monkeypatch, capsys, tmp_path):
    from drive_server import cli

    monkeypatch.setattr(cli, "default_model_path", lambda: tmp_path / "unity.onnx")
    assert cli.main(["--port", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("drive_server: error: no --model")
    assert "unity.onnx" in err[0]


def test_the_limit_flags_reach_the_server_as_one_wire_limits(monkeypatch, tmp_path):
    """Issue 51: ServerConfig copied WireLimits' fields; now it nests the one object the command line built."""
    from dataclasses import fields

    import drive_server.wire.server
    from drive_server import cli
    from drive_server.wire.limits import WireLimits
    from drive_server.wire.server_config import ServerConfig
    from protocol.errors import UserError

    assert not {f.name for f in fields(WireLimits)} & {f.name for f in fields(ServerConfig)}
    seen = []

    class Stop(UserError):
        pass

    def capture(pipeline, config):
        seen.append(config)
        raise Stop("stop here")

    monkeypatch.setattr(drive_server.wire.server, "DriveServer", capture)
    model = build_shallow(tmp_path / "m.onnx")
    assert cli.main(["--model", str(model), "--port", "0", "--max-connections", "7", "--header-timeout", "3",
                     "--max-pending", "5", "--idle-evict", "2"]) == 2
    assert seen[0].limits == WireLimits(max_connections=7, header_timeout_s=3.0, max_pending_replies=5,
                                        idle_evict_s=2.0)


def test_default_model_path_is_the_bundled_package_file():
    path = default_model_path()
    assert path.name == "unity.onnx" and path.parent == REPO / "models" / "pretrained"


def test_port_in_use_exits_2(tmp_path):
    import socket

    model = build_shallow(tmp_path / "m.onnx")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        result = run_server_cli("--model", str(model), "--port", str(s.getsockname()[1]))
    assert result.returncode == 2 and "cannot listen" in result.stderr


def test_deployment_imports_no_training_packages():
    code = ("import sys, drive_server.cli, drive_server.wire.server, tools.wire.unity_client, tools.wire.frames, "
            "tools.commands.replay; "
            "from drive_server.serving.models_dir import default_model_path; default_model_path(); "
            "bad = sorted(m for m in ('torch', 'onnx', 'matplotlib') if m in sys.modules); print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
    assert out.stderr.strip() == ""  # eventlet's deprecation banner is filtered


def test_help():
    out = run_server_cli("--help")
    assert out.returncode == 0 and "--telemetry-speed-unit" in out.stdout and "--stats-json" in out.stdout
