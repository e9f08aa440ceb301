"""Benchmark models (onnx.helper builders), ``rbc bench`` and ``rbc replay`` end to end (behaviour, not speed)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers_server import SAMPLE_LOG, build_shallow

from tools.cli import main as rbc
from tools.wire.server_process import ServerProcess

onnx = pytest.importorskip("onnx", reason="the benchmark models are built with the onnx package")
ort = pytest.importorskip("onnxruntime")

from drive_server.serving.contract import METADATA_KEY, PreprocessContract  # noqa: E402
from models.networks.architectures import PILOTNET, SHALLOW, SHALLOW_WIDE  # noqa: E402
from tools.bench.onnx_builders import ARCHS, build_model, count_parameters  # noqa: E402


@pytest.mark.parametrize(("arch", "params"), [(SHALLOW, 14_065), (PILOTNET, 252_219), (SHALLOW_WIDE, 46_065)])
def test_builders_match_the_papers_architectures(arch, params):
    model = build_model(arch, seed=0)
    assert count_parameters(model) == params
    meta = {p.key: p.value for p in model.metadata_props}
    contract = PreprocessContract.from_json(meta[METADATA_KEY])
    assert (contract.height, contract.width, contract.layout) == (arch.height, arch.width, "nhwc")
    session = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    out = session.run(None, {"image": np.zeros((2, arch.height, arch.width, 3), np.float32)})[0]
    assert out.shape == (2, 1)
    assert ARCHS[arch.name] is arch


def test_builders_are_deterministic_and_validate():
    assert build_model(SHALLOW, seed=4).SerializeToString() == build_model(SHALLOW, seed=4).SerializeToString()
    with pytest.raises(ValueError, match="does not match"):
        build_model(SHALLOW, contract=PreprocessContract(width=200, height=66))


@pytest.mark.slow
def test_rbc_bench_runs_and_writes_json(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert rbc(["bench", "--frames", "30", "--warmup", "5", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "round trip (client)" in printed and "server inference" in printed and "telemetry/s" in printed
    run = json.loads(out.read_text())["runs"][0]
    assert run["clients"] == 1 and run["frames_per_client"] == 30
    assert set(run["round_trip_ms"]) >= {"p50", "p90", "p99", "max"}
    assert run["server"]["total"]["frames"] == 35 and run["server"]["total"]["malformed"] == 0


@pytest.mark.slow
def test_rbc_bench_concurrent_clients_against_a_running_server(tmp_path, capsys):
    model = build_shallow(tmp_path / "m.onnx")
    with ServerProcess(model, ["--log-every", "0"]) as server:
        assert rbc(["bench", "--server", server.url, "--clients", "2", "--frames", "20", "--warmup", "2",
                    "--json", str(tmp_path / "b.json")]) == 0
    run = json.loads((tmp_path / "b.json").read_text())["runs"][0]
    assert run["clients"] == 2 and run["telemetry_per_s"] > 0


@pytest.mark.slow
def test_rbc_replay(tmp_path, capsys):
    model = build_shallow(tmp_path / "m.onnx")
    with ServerProcess(model, ["--log-every", "0"]) as server:
        assert rbc(["replay", "--server", server.url, "--log", str(SAMPLE_LOG), "--frames", "8",
                    "--null-every", "4", "--locale", "comma"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert sum("-> steer" in ln for ln in lines) == 6 and sum("-> manual" in ln for ln in lines) == 2
    assert lines[-1].startswith("8 frames (2 manual)")


def test_rbc_replay_unreachable_server(capsys):
    assert rbc(["replay", "--server", "http://127.0.0.1:9", "--log", str(SAMPLE_LOG), "--frames", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rbc replay: error: replay to http://127.0.0.1:9 failed")


def test_rbc_bench_without_onnx_says_what_to_do(monkeypatch, capsys):
    import sys

    monkeypatch.setitem(sys.modules, "onnx", None)  # as if the train extra were not installed
    monkeypatch.delitem(sys.modules, "tools.bench.onnx_builders", raising=False)
    assert rbc(["bench", "--frames", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("rbc bench: error: ") and "--model" in err and 'pip install -e ".[train]"' in err


def test_the_benchmarks_find_the_real_frames_of_a_checkout():
    """Moving a module must not silently switch a benchmark to synthetic frames."""
    from tools.bench.fuzz_campaign import DEFAULT_LOG as FUZZ_LOG
    from tools.bench.latency import DEFAULT_LOG, load_frames

    assert DEFAULT_LOG.is_dir() and FUZZ_LOG == DEFAULT_LOG
    frames, source = load_frames(None)
    assert "synthetic" not in source and len(frames) > 30
