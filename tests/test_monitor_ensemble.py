"""#53: the ensemble monitor. Its score graph takes the served network's steering beside the frame; the score is
the served steering's distance to the members' mean (plus their spread), members of exactly the served model's
contract, two at least; the server feeds the steering through one function (the bundled files' monitors:
test_monitor_bundled.py). Tiny members: weight-noised copies of generalist.onnx."""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path

import numpy as np
import pytest
from helpers_server import REPO, SAMPLE_LOG

from drive_server.serving.client_monitor import ClientMonitor, MonitorMode, MonitorPolicy
from drive_server.serving.model import SteeringModel
from drive_server.serving.monitor import FRAME, STEERING, MonitorGraph, MonitorSpec
from drive_server.serving.pipeline import DriveConfig, DrivePipeline
from drive_server.serving.preprocess import preprocess
from protocol import decode_image, parse_telemetry
from tools.wire.frames import log_frames

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

PRETRAINED = REPO / "models" / "pretrained"
GENERALIST = PRETRAINED / "generalist.onnx"
FRAMES = log_frames(SAMPLE_LOG)
TWO = MonitorSpec("scripted", warn=1.0, alarm=2.0, window=3, inputs=(FRAME, STEERING))


def _outputs(path: Path, x: np.ndarray) -> np.ndarray:
    """A model's own output on each frame, in a session of its own (what the graph must agree with)."""
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    name = session.get_inputs()[0].name
    return np.array([float(session.run(None, {name: x[i:i + 1]})[0].reshape(-1)[0]) for i in range(len(x))])


@pytest.fixture(scope="module")
def members(tmp_path_factory) -> list[Path]:
    from tools.monitoreval.modelfiles import degraded_model

    folder = tmp_path_factory.mktemp("members")
    return [degraded_model(GENERALIST, folder, 0.1, seed) for seed in (1, 2, 3)]


@pytest.fixture(scope="module")
def frames() -> np.ndarray:
    return (np.random.default_rng(7).random((6, 64, 64, 3), dtype=np.float32) - 0.5).astype(np.float32)


@pytest.mark.parametrize("spread", [False, True])
def test_the_score_is_the_served_steering_against_the_members_mean(members, frames, spread):
    from models.monitoring.ensemble import ensemble_score_graph

    graph = MonitorGraph(ensemble_score_graph(GENERALIST, members, spread=spread), "t", (FRAME, STEERING))
    served = _outputs(GENERALIST, frames)
    outs = np.stack([_outputs(m, frames) for m in members])
    want = np.abs(served - outs.mean(axis=0)) + (outs.std(axis=0) if spread else 0.0)
    got = [graph.score(frames[i:i + 1], float(served[i])) for i in range(len(frames))]
    assert np.allclose(got, want, atol=1e-5) and min(want) > 0
    moved = graph.score(frames[:1], float(served[0]) + 0.25)  # the served steering is what it is told
    assert moved == pytest.approx(abs(served[0] + 0.25 - outs[:, 0].mean()) + (outs[:, 0].std() if spread else 0),
                                  abs=1e-5)
    with pytest.raises(ValueError, match="served steering"):
        graph.score(frames[:1])


def _calibration_set(folder: Path, runs: int = 2, n: int = 40) -> Path:
    """rbc monitor failures --set calibration's files, synthetic: nominal runs on training worlds, no take-over."""
    from models.monitoring.failures import FailureRun, quantise, save_run

    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(3)
    for k in range(runs):
        x = rng.random((n, 64, 64, 3), dtype=np.float32) - 0.5
        save_run(folder / f"nominal-{k}.npz", FailureRun(f"nominal-{k}", quantise(x), np.arange(n) / 15.0, (),
                                                         {"group": "nominal", "seed_range": "train"}))
    return folder


@pytest.fixture(scope="module")
def calibration(tmp_path_factory) -> Path:
    return _calibration_set(tmp_path_factory.mktemp("calibration"))


def _fit(members: list[Path], calibration: Path, out: Path, *extra: str, model: Path = GENERALIST) -> int:
    from tools.cli import main

    args = ["monitor", "fit", str(model), "--score", "ensemble", "--calibration", str(calibration), "--out", str(out)]
    for m in members:
        args += ["--member", str(m)]
    return main([*args, *extra])


def _unmirrored(src: Path, dst: Path) -> Path:
    """``src`` whose record says it does not answer the mirror average (a member rbc mirror was not run on)."""
    proto = onnx.load(str(src))
    for prop in proto.metadata_props:
        if prop.key == "rbc.model":
            prop.value = json.dumps({**json.loads(prop.value), "mirror_average": False})
    onnx.save(proto, str(dst))
    return dst


@pytest.mark.parametrize("case, problem", [
    ("single", "at least 2 members"),
    ("contract", "preprocessing differs from generalist.onnx's"),
    ("served", "the same file as the served model"),
    ("mirror", "does not answer the mirror average"),
])
def test_a_wrong_contract_member_or_a_single_one_is_refused_in_one_line(members, calibration, tmp_path, capsys,
                                                                         case, problem):
    chosen = {"single": members[:1], "contract": [members[0], PRETRAINED / "unity.onnx"],
              "served": [members[0], GENERALIST],
              "mirror": [members[0], _unmirrored(members[1], tmp_path / "plain.onnx")]}[case]
    out = tmp_path / "out.onnx"
    assert _fit(chosen, calibration, out) == 2
    err = capsys.readouterr().err.strip()
    assert problem in err and len(err.splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()


def test_members_are_for_the_ensemble_score_only(members, calibration, tmp_path, capsys):
    assert _fit(members, calibration, tmp_path / "o.onnx", "--score", "shift") == 2
    assert "members (--member) are for --score ensemble" in capsys.readouterr().err


def test_a_spec_names_its_inputs_and_the_graph_must_match(members):
    from drive_server.serving.monitor import MonitorError
    from models.monitoring.ensemble import ensemble_score_graph
    from protocol.errors import BadValue

    assert MonitorSpec.from_json(TWO.to_json()) == TWO and json.loads(TWO.to_json())["inputs"] == ["frame", "steering"]
    with pytest.raises(BadValue, match="'inputs' must be"):
        MonitorSpec.from_json('{"score": "x", "warn": 1, "alarm": 2, "inputs": ["steering"]}')
    graph = ensemble_score_graph(GENERALIST, members[:2])
    with pytest.raises(MonitorError, match="must have 1 input"):
        MonitorGraph(graph, "m.onnx")  # a two-input graph under a frame-only spec


class _Scripted:
    """A two-input monitor graph that keeps what it is shown."""

    def __init__(self, how: str = "ok") -> None:
        self.how = how
        self.seen: list[float | None] = []

    def score(self, x: np.ndarray, steering: float | None = None) -> float:
        self.seen.append(steering)
        if self.how == "raise":
            raise RuntimeError("boom")
        if self.how == "slow":
            time.sleep(0.01)
        return math.nan if self.how == "nan" else 0.0


def test_the_pipeline_feeds_the_served_networks_own_steering(members):
    """Before the gain, the clamping and the smoothing; the env's way in (no steering at hand) runs the network."""
    model = SteeringModel(GENERALIST)
    pipeline = DrivePipeline(model, DriveConfig(gain=2.0, smoothing=0.5,
                                                monitor=MonitorPolicy(MonitorMode.WARN, budget_ms=None)))
    graph = _Scripted()
    monitor = ClientMonitor(graph, TWO, pipeline.config.monitor, "t")  # type: ignore[arg-type]
    smoother = pipeline.smoother()
    xs = [preprocess(decode_image(f.payload()["image"], reduce=pipeline.reduce), model.contract) for f in FRAMES[:5]]
    sent = [pipeline.run(parse_telemetry(f.payload()), smoother, monitor)[0].steering for f in FRAMES[:5]]
    raw = [model.predict(x) for x in xs]
    assert graph.seen == raw and sent != raw  # the network's own output, not the command sent
    assert pipeline.observe(monitor, xs[0]) is not None and graph.seen[-1] == raw[0]  # run here when not given
    assert pipeline.observe(None, xs[0]) is None


@pytest.mark.parametrize("how", ["raise", "nan", "slow", "no_steering", "network"])
def test_a_two_input_monitor_that_fails_leaves_steering_untouched_and_is_reported_once(how, caplog):
    model = SteeringModel(GENERALIST)
    policy = MonitorPolicy(mode=MonitorMode.ACT, budget_ms=1.0, strikes=2)
    pipeline = DrivePipeline(model, DriveConfig(monitor=policy))
    reference = DrivePipeline(model, DriveConfig(monitor=MonitorPolicy(mode=MonitorMode.OFF)))
    monitor = ClientMonitor(_Scripted("ok" if how in ("no_steering", "network") else how), TWO, policy, "c2")  # type: ignore[arg-type]
    if how == "network":  # the env's way in, where running the network for the monitor raises
        pipeline.model = type("Broken", (), {"predict": lambda self, x: 1 / 0})()  # type: ignore[assignment]
    with caplog.at_level(logging.WARNING, logger="drive_server.serving.client_monitor"):
        if how in ("no_steering", "network"):
            x = np.zeros((1, 64, 64, 3), np.float32)
            for _ in range(3):
                assert (monitor.observe(x) if how == "no_steering" else pipeline.observe(monitor, x)) is None
        else:
            got = [pipeline.run(parse_telemetry(f.payload()), None, monitor)[0] for f in FRAMES[:6]]
            assert got == [reference.run(parse_telemetry(f.payload()))[0] for f in FRAMES[:6]]
    assert monitor.failed and monitor.last is None
    lines = [r for r in caplog.records if "monitor switched off" in r.getMessage()]
    assert len(lines) == 1 and "client c2" in lines[0].getMessage()


@pytest.mark.slow
def test_fit_writes_a_file_drive_server_serves_with_the_ensemble_monitor(members, calibration, tmp_path, capsys):
    """rbc monitor fit --score ensemble on a tiny synthetic calibration set: thresholds from the served model's
    own steering on the stored frames, the steering graph untouched, and drive_server --monitor warn serves it."""
    from models.monitoring.calibrate import window_means
    from models.monitoring.failures import load_run, run_files
    from tools.wire.server_process import ServerProcess
    from tools.wire.unity_client import UnityWireClient

    out = tmp_path / "ens.onnx"
    assert _fit(members[:2], calibration, out) == 0
    assert "monitor ensemble, warning at" in capsys.readouterr().out
    spec, graph = SteeringModel(out).monitor()
    assert spec.score == "ensemble" and spec.inputs == (FRAME, STEERING) and graph.wants_steering
    assert [m["file"] for m in spec.calibration["members"]] == [m.name for m in members[:2]]
    assert spec.calibration["frames"] == 80 and spec.calibration["short"] == ["warn", "alarm"]
    nominal = []
    for path in run_files([calibration]):
        x = load_run(path).floats()
        served = _outputs(GENERALIST, x)
        outs = np.stack([_outputs(m, x) for m in members[:2]])
        nominal.append(window_means(np.abs(served - outs.mean(axis=0)) + outs.std(axis=0), spec.window))
    assert spec.alarm == pytest.approx(max(float(m.max()) for m in nominal), rel=1e-4)  # short: the maximum

    plain, monitored = SteeringModel(GENERALIST), SteeringModel(out)
    pipeline = DrivePipeline(monitored, DriveConfig(monitor=MonitorPolicy(MonitorMode.WARN)))
    monitor = pipeline.client_monitor("t")
    reference = DrivePipeline(plain)
    for frame in FRAMES[:4]:
        command, _ = pipeline.run(parse_telemetry(frame.payload()), pipeline.smoother(), monitor)
        assert command == reference.run(parse_telemetry(frame.payload()), reference.smoother())[0]
        x = preprocess(decode_image(frame.payload()["image"], reduce=pipeline.reduce), plain.contract)
        outs = np.array([_outputs(m, x)[0] for m in members[:2]])
        assert monitor.last.score == pytest.approx(abs(plain.predict(x) - outs.mean()) + outs.std(), abs=1e-5)

    again = tmp_path / "again.onnx"  # a fresh calibration keeps the two inputs
    from tools.cli import main

    assert main(["monitor", "fit", str(out), "--score", "keep", "--calibration", str(calibration),
                 "--out", str(again)]) == 0
    kept = SteeringModel(again).monitor()[0]
    assert kept.inputs == (FRAME, STEERING) and kept.calibration["members"] == spec.calibration["members"]

    srv = ServerProcess(out, ["--log-every", "0", "--monitor", "warn"])
    srv.start()
    try:
        with UnityWireClient(srv.url) as client:
            for frame in FRAMES[:4]:
                client.send_telemetry(dict(frame.payload(), speed="10.0"))
                packet = client._receive_packet(time.monotonic() + 10)
                assert packet.startswith('42["steer",')
    finally:
        assert srv.stop() == 0, srv.log()
    log = srv.log()
    assert "monitor: ensemble (warn)" in log and "monitor switched off" not in log and "Traceback" not in log


def test_the_benchmarks_wrappers_pass_the_steering_on(members, frames):
    """rbc monitor eval's shadow monitors and rbc monitor failures' recorder stand where the client's monitor does:
    the served steering reaches the driving monitor and a two-input shadow alike."""
    from models.monitoring.ensemble import ensemble_score_graph
    from tools.monitoreval.failruns import _Recording
    from tools.monitoreval.runner import _Shadowed

    policy = MonitorPolicy(MonitorMode.WARN, budget_ms=None)
    graph = _Scripted()
    shadow = MonitorGraph(ensemble_score_graph(GENERALIST, members[:2]), "s", (FRAME, STEERING))
    wrapped = _Recording(_Shadowed(ClientMonitor(graph, TWO, policy), [shadow]))  # type: ignore[arg-type]
    assert wrapped.observe(frames[:1], 0.25) is not None and wrapped.wants_steering
    assert graph.seen == [0.25] and len(wrapped.inputs) == 1
    assert wrapped.primary.scores[0] == [pytest.approx(shadow.score(frames[:1], 0.25))]
