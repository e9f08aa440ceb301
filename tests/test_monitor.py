"""The misbehaviour monitor in drive_server: its state machine on scripted scores, its file format, a monitor
that fails never touching steering, ``act`` slowing and stopping the car, and calibration that never sees held-out
runs. Behaviour only, never timing."""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path

import numpy as np
import pytest
from helpers_server import SAMPLE_LOG, build_shallow, run_server_cli

from drive_server.serving.client_monitor import (
    ClientMonitor,
    Level,
    MonitorMode,
    MonitorPolicy,
    MonitorState,
    at_frame_rate,
)
from drive_server.serving.model import SteeringModel
from drive_server.serving.monitor import MONITOR_GRAPH_KEY, MONITOR_KEY, MonitorError, MonitorSpec, encode_graph
from drive_server.serving.pipeline import DriveConfig, DrivePipeline
from protocol import parse_telemetry
from tools.wire.frames import log_frames

onnx = pytest.importorskip("onnx")

SPEC = MonitorSpec("scripted", warn=1.0, alarm=2.0, window=3)


def _levels(scores: list[float]) -> list[str]:
    state = MonitorState(SPEC, MonitorPolicy(release_frames=2))
    return [state.update(s).level.label for s in scores]


def test_the_state_machine_warns_alarms_and_hands_back_on_the_window_mean():
    # window of 3, means: 0 0 .5 | 1 1.83 | 2.17 2.5 1.67 | .83 0 ...: held in alarm while the mean is above the
    # warning threshold, handed back after two frames below it
    levels = _levels([0, 0, 1.5, 1.5, 2.5, 2.5, 2.5, 0, 0, 0, 0, 0, 0])
    assert levels == ["normal", "normal", "normal", "warning", "warning", "alarm", "alarm",
                      "alarm", "alarm", "normal", "normal", "normal", "normal"]
    # the hand-back waits for release_frames frames whose mean is below the warning threshold
    state = MonitorState(SPEC, MonitorPolicy(release_frames=2))
    for s in [3, 3, 3]:
        state.update(s)
    assert state.episodes == {"warning": 0, "alarm": 1}


def test_on_a_recording_at_another_rate_the_window_and_hand_back_keep_their_seconds():
    """A real recording at 9 Hz averaged over 15 frames would average 1.7 s, not the one second calibrated on."""
    spec, policy = at_frame_rate(MonitorSpec("s", 1.0, 2.0, window=15), MonitorPolicy(release_frames=15), 9.0)
    assert (spec.window, policy.release_frames) == (9, 9)
    assert at_frame_rate(MonitorSpec("s", 1.0, 2.0, window=15), MonitorPolicy(), 15.0)[0].window == 15
    assert at_frame_rate(MonitorSpec("s", 1.0, 2.0, window=15), MonitorPolicy(), 1.0)[0].window == 1
    from protocol.errors import BadValue

    with pytest.raises(BadValue, match="frame rate"):
        at_frame_rate(SPEC, MonitorPolicy(), float("nan"))


def test_drive_log_monitors_a_recording_at_its_own_frame_rate(models):
    """rbc drive-log's monitor gets the log's rate (the median interval between its frames)."""
    import numpy as np

    from tools.drivelog.drivers import recording_rate_hz
    from tools.drivelog.path import RecordedDrive

    log = RecordedDrive(frames=[], steering=np.zeros(4), speed=np.zeros(4), dt=np.array([0.11, 0.11, 0.12, 0.0]),
                        session=np.zeros(4, int), arc=np.zeros(4))
    assert recording_rate_hz(log) == pytest.approx(1 / 0.11)
    pipeline = DrivePipeline(SteeringModel(models["calm"]), DriveConfig(monitor=MonitorPolicy(MonitorMode.WARN)))
    monitor = pipeline.client_monitor(frame_rate_hz=recording_rate_hz(log))
    assert monitor is not None and monitor.state.spec.window == 2  # the fixture's window of 3 frames at 15 Hz


def test_a_single_spike_below_the_window_mean_raises_nothing():
    assert set(_levels([0, 0, 2.9, 0, 0, 0])) == {"normal"}


def test_a_non_finite_score_is_a_fault_not_a_state():
    from drive_server.serving.client_monitor import MonitorFault

    with pytest.raises(MonitorFault):
        MonitorState(SPEC).update(math.nan)


@pytest.mark.parametrize("text, problem", [
    ("{", "not valid JSON"),
    ('{"score": "x", "warn": 2, "alarm": 1}', "below"),
    ('{"score": "x", "warn": "a", "alarm": 1}', "finite number"),
    ('{"score": "x", "warn": 1, "alarm": 2, "window": 0}', "window"),
    ('{"score": "x", "warn": 1, "alarm": 2, "extra": 1}', "unknown keys"),
])
def test_a_bad_spec_is_one_line(text, problem):
    from protocol.errors import BadValue

    with pytest.raises(BadValue, match=problem) as info:
        MonitorSpec.from_json(text)
    assert "\n" not in str(info.value)


def _brightness_graph() -> bytes:
    """A monitor graph: the mean of the preprocessed input (-0.5 black .. 0.5 white), batch 1."""
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("ReduceMean", ["input"], ["score"], keepdims=0)], "brightness",
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, ["batch", 64, 64, 3])],
        [helper.make_tensor_value_info("score", TensorProto.FLOAT, [])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return model.SerializeToString()


def _with_monitor(src: Path, dst: Path, spec: MonitorSpec, graph: bytes | None = None, raw: dict | None = None) -> Path:
    proto = onnx.load(str(src))
    meta = raw if raw is not None else {MONITOR_KEY: spec.to_json(), MONITOR_GRAPH_KEY: encode_graph(graph or b"")}
    for key, value in meta.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(proto, str(dst))
    return dst


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("monitor")
    plain = build_shallow(folder / "plain.onnx", seed=1)
    # the sample's frames score about -0.1: warnings from -0.5, alarms from -0.2, so every frame alarms
    alarming = _with_monitor(plain, folder / "alarming.onnx", MonitorSpec("brightness", -0.5, -0.2, 3),
                             _brightness_graph())
    calm = _with_monitor(plain, folder / "calm.onnx", MonitorSpec("brightness", 0.4, 0.45, 3), _brightness_graph())
    return {"plain": plain, "alarming": alarming, "calm": calm, "folder": folder}


FRAMES = log_frames(SAMPLE_LOG)


def _drive(path: Path, mode: str, n: int = 8, speed: float | None = None):
    pipeline = DrivePipeline(SteeringModel(path), DriveConfig(monitor=MonitorPolicy(mode=MonitorMode(mode))))
    monitor = pipeline.client_monitor("t")
    out = []
    for frame in FRAMES[:n]:
        payload = frame.payload()
        if speed is not None:
            payload["speed"] = str(speed)
        command, _ = pipeline.run(parse_telemetry(payload), pipeline.smoother(), monitor)
        out.append((command, monitor.last if monitor is not None else None))
    return out


def test_a_model_without_a_monitor_serves_exactly_as_before(models):
    plain = _drive(models["plain"], "act")
    assert all(reading is None for _, reading in plain)
    calm = _drive(models["calm"], "act")
    assert [c for c, _ in calm] == [c for c, _ in plain]  # a monitor in normal state changes nothing
    assert {r.level for _, r in calm} == {Level.NORMAL}


def test_act_brakes_on_an_alarm_and_never_changes_steering(models):
    warn, act, off = (_drive(models["alarming"], m, speed=15.0) for m in ("warn", "act", "off"))
    assert [c for c, _ in warn] == [c for c, _ in off]  # warn reports only
    assert [c.steering for c, _ in act] == [c.steering for c, _ in off]
    assert act[-1][1].level == Level.ALARM and act[-1][0].throttle == -1.0
    stopped = _drive(models["alarming"], "act", speed=0.0)
    assert stopped[-1][0].throttle == 0.0  # stopped: it waits, no reverse


def test_act_slows_on_a_warning_through_the_control_law(models):
    pipeline = DrivePipeline(SteeringModel(models["calm"]), DriveConfig(monitor=MonitorPolicy(mode=MonitorMode.ACT)))
    from drive_server.serving.client_monitor import MonitorReading

    normal = pipeline.control(0.1, 10.0, MonitorReading(0, 0, Level.NORMAL))
    slowed = pipeline.control(0.1, 10.0, MonitorReading(0, 0, Level.WARNING))
    assert slowed.steering == normal.steering and slowed.throttle < normal.throttle


class _Broken:
    def __init__(self, how: str) -> None:
        self.how = how

    def score(self, x: np.ndarray) -> float:
        if self.how == "raise":
            raise RuntimeError("boom")
        if self.how == "slow":
            time.sleep(0.01)
            return 0.0
        return math.nan


@pytest.mark.parametrize("how", ["raise", "nan", "slow"])
def test_a_monitor_that_fails_leaves_steering_untouched_and_is_reported_once(models, how, caplog):
    pipeline = DrivePipeline(SteeringModel(models["calm"]), DriveConfig(monitor=MonitorPolicy(mode=MonitorMode.ACT)))
    reference = _drive(models["plain"], "off", n=6)
    monitor = ClientMonitor(_Broken(how), SPEC, MonitorPolicy(mode=MonitorMode.ACT, budget_ms=1.0, strikes=2), "c1")
    with caplog.at_level(logging.WARNING, logger="drive_server.serving.client_monitor"):
        commands = [pipeline.run(parse_telemetry(f.payload()), pipeline.smoother(), monitor)[0] for f in FRAMES[:6]]
    assert commands == [c for c, _ in reference]
    assert monitor.failed and monitor.last is None
    lines = [r for r in caplog.records if "monitor switched off" in r.getMessage()]
    assert len(lines) == 1 and "client c1" in lines[0].getMessage()


def test_a_broken_monitor_is_one_line_and_off_still_serves(models, tmp_path):
    half = _with_monitor(models["plain"], tmp_path / "half.onnx", SPEC, raw={MONITOR_KEY: SPEC.to_json()})
    garbage = _with_monitor(models["plain"], tmp_path / "garbage.onnx", SPEC, graph=b"not onnx")
    for path, problem in ((half, "needs both"), (garbage, "cannot be loaded")):
        with pytest.raises(MonitorError, match=problem):
            SteeringModel(path).monitor()
        DrivePipeline(SteeringModel(path), DriveConfig(monitor=MonitorPolicy(mode=MonitorMode.OFF)))
    done = run_server_cli("--model", str(garbage), "--port", "0", "--monitor", "warn")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "cannot be loaded" in done.stderr and "--monitor off" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_the_recording_gets_the_monitor_beside_the_unchanged_log(models, tmp_path):
    from drive_server.observing.recorder import MONITOR_LOG, Recorder
    from protocol.datalog import read_log

    rec = Recorder(tmp_path / "rec")
    for command, reading in _drive(models["alarming"], "warn", n=5):
        rec.record(FRAMES[0].payload()["image"], command, 10.0, reading)
    rec.close()
    samples, _ = read_log(tmp_path / "rec")
    rows = (tmp_path / "rec" / MONITOR_LOG).read_text().splitlines()
    assert len(samples) == 5 and rows[0] == "frame,score,mean,state" and len(rows) == 6
    assert rows[-1].endswith(",alarm") and rows[1].split(",")[0] == samples[0].center.name


def test_calibration_never_sees_training_or_held_out_runs(tmp_path):
    from models.monitoring.fit import FitPlan
    from models.monitoring.frames import load_runs
    from protocol.errors import BadValue

    with pytest.raises(BadValue, match="other runs"):
        FitPlan(Path("m.onnx"), Path("o.onnx"), (SAMPLE_LOG,), (SAMPLE_LOG,))
    import shutil

    held_out = shutil.copytree(SAMPLE_LOG, tmp_path / "eval_worlds")
    (held_out / "worlds.csv").write_text("world_seed,seed_range,first_row,last_row\n9000000,eval,1,5\n")
    contract = SteeringModel(build_shallow(tmp_path / "m.onnx")).contract
    with pytest.raises(BadValue, match="evaluation world"):
        load_runs([held_out], contract)


def test_calibration_thresholds_are_quantiles_of_the_window_mean():
    from models.monitoring.calibrate import FRAMES_PER_HOUR, calibrate, window_means

    assert np.allclose(window_means(np.array([1.0, 3, 5, 7]), 2), [1, 2, 4, 6])
    rng = np.random.default_rng(0)
    runs = [rng.gamma(2.0, 1.0, FRAMES_PER_HOUR // 2) for _ in range(4)]  # two hours
    cal = calibrate(runs, 15, warnings_per_hour=10, alarms_per_hour=1)
    means = np.concatenate([window_means(r, 15) for r in runs])
    assert (means >= cal.warn).sum() == pytest.approx(20, abs=2)  # ~10 an hour over two hours
    assert (means >= cal.alarm).sum() == pytest.approx(2, abs=1)
    assert cal.record["short"] == [] and cal.record["hours"] == pytest.approx(2.0)
    short = calibrate(runs[:1], 15, warnings_per_hour=10, alarms_per_hour=1)
    assert short.record["short"] == ["alarm"] and short.alarm == pytest.approx(max(window_means(runs[0], 15)))


@pytest.mark.slow
def test_the_unity_wire_is_unchanged_and_the_server_log_says_the_alarm(models):
    """The real server with a monitor in act: the simulator still gets exactly steering_angle and throttle (the
    brake as a negative throttle), the start-up line names the monitor, the alarm is logged once."""
    import json

    from tools.wire.server_process import ServerProcess
    from tools.wire.unity_client import UnityWireClient

    srv = ServerProcess(models["alarming"], ["--log-every", "0", "--monitor", "act"])
    srv.start()
    try:
        with UnityWireClient(srv.url) as client:
            for frame in FRAMES[:6]:
                client.send_telemetry(dict(frame.payload(), speed="10.0"))
                packet = client._receive_packet(time.monotonic() + 10)
                payload = json.loads(packet[2:])[1]
                assert packet.startswith('42["steer",') and set(payload) == {"steering_angle", "throttle"}
    finally:
        assert srv.stop() == 0, srv.log()
    log = srv.log()
    assert float(payload["throttle"]) == -1.0
    assert "monitor: brightness (act), warning at -0.5, alarm at -0.2" in log
    assert log.count("monitor alarm") == 1 and "Traceback" not in log


@pytest.mark.slow
def test_rbc_monitor_fit_attaches_a_calibrated_monitor_and_leaves_steering_alone(tmp_path, capsys):
    """fit (autoencoder), a fresh calibration of it (keep) and the shift monitor, on the test recording: the written
    file steers exactly as its source, carries the monitor, and the thresholds come from the calibration runs."""
    import shutil

    pytest.importorskip("torch")
    from protocol import decode_image
    from tools.cli import main

    src = build_shallow(tmp_path / "m.onnx", seed=2)
    calib = shutil.copytree(SAMPLE_LOG, tmp_path / "calib")  # other runs by path (the same frames: a test)
    out = tmp_path / "mon.onnx"
    assert main(["monitor", "fit", str(src), "--data", str(SAMPLE_LOG), "--calibration", str(calib),
                 "--epochs", "1", "--out", str(out)]) == 0
    assert "monitor autoencoder, warning at" in capsys.readouterr().out
    spec = SteeringModel(out).monitor()[0]
    assert spec.score == "autoencoder" and spec.calibration["frames"] == 36 and spec.calibration["short"]
    assert spec.warn <= spec.alarm == pytest.approx(spec.calibration["nominal_max"])
    rgb = decode_image(FRAMES[0].payload()["image"])
    assert DrivePipeline(SteeringModel(out)).steer(rgb) == DrivePipeline(SteeringModel(src)).steer(rgb)
    again = tmp_path / "again.onnx"
    assert main(["monitor", "fit", str(out), "--score", "keep", "--calibration", str(calib),
                 "--alarms-per-hour", "0.5", "--warnings-per-hour", "0.5", "--out", str(again)]) == 0
    kept = SteeringModel(again).monitor()
    assert kept[0].score == "autoencoder" and kept[0].calibration["recalibrated"]
    assert kept[1].model_bytes == SteeringModel(out).monitor()[1].model_bytes
    shift = tmp_path / "shift.onnx"
    assert main(["monitor", "fit", str(src), "--score", "shift", "--calibration", str(calib), "--out",
                 str(shift)]) == 0
    assert SteeringModel(shift).monitor()[0].score == "shift"
    assert main(["monitor", "fit", str(src), "--calibration", str(calib), "--out", str(tmp_path / "x.onnx")]) == 2


def test_a_busy_moment_does_not_switch_the_monitor_off_and_offline_tools_have_no_budget():
    """One slow frame is a hiccup; most of a second over budget is a slow monitor. Tools on simulated time (sim,
    drive-log, the benchmark, the env) run without a budget, so a busy machine cannot change their figures (it
    switched the monitor off in a quarter of the first benchmark's runs)."""
    slow = _Broken("slow")  # 10 ms a frame
    hiccup = ClientMonitor(_Flaky(), SPEC, MonitorPolicy(budget_ms=5.0))
    for _ in range(30):
        assert hiccup.observe(np.zeros(1)) is not None
    monitor = ClientMonitor(slow, SPEC, MonitorPolicy(budget_ms=5.0))
    readings = [monitor.observe(np.zeros(1)) for _ in range(15)]
    assert monitor.failed and readings.count(None) == 4  # off at the 12th slow frame of the last 15
    unbudgeted = ClientMonitor(slow, SPEC, MonitorPolicy(budget_ms=None))
    assert all(unbudgeted.observe(np.zeros(1)) is not None for _ in range(20)) and not unbudgeted.failed


class _Flaky:
    """Slow on every 5th frame only."""

    def __init__(self) -> None:
        self.n = 0

    def score(self, x: np.ndarray) -> float:
        self.n += 1
        if self.n % 5 == 0:
            time.sleep(0.01)
        return 0.0
