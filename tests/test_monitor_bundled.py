"""#53: the monitors the bundled model files carry: the single-input autoencoders read and score exactly as stored,
and generalist.onnx's MC-dropout is scored by the server with the served network's own steering, its steering
untouched."""

from __future__ import annotations

import base64
import json

import numpy as np
import pytest
from test_monitor_ensemble import FRAMES, GENERALIST, PRETRAINED

from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
from drive_server.serving.model import SteeringModel
from drive_server.serving.monitor import FRAME, MONITOR_KEY, STEERING
from drive_server.serving.pipeline import DriveConfig, DrivePipeline
from drive_server.serving.preprocess import preprocess
from protocol import decode_image, parse_telemetry

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")


@pytest.mark.parametrize("name", ["generalist_pilotnet.onnx", "unity.onnx"])
def test_the_bundled_single_input_monitors_read_and_score_as_before(name):
    """Their spec reads back to the very text stored (no inputs key), the graph takes the frame only, and the
    server's score is the graph's own answer on the frame, bit for bit."""
    path = PRETRAINED / name
    meta = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    spec, graph = SteeringModel(path).monitor()
    assert spec.inputs == (FRAME,) and not spec.wants_steering and not graph.wants_steering
    assert spec.to_json() == meta[MONITOR_KEY] and "inputs" not in json.loads(meta[MONITOR_KEY])
    session = ort.InferenceSession(base64.b64decode(meta["rbc.monitor.onnx"]), providers=["CPUExecutionProvider"])
    model = SteeringModel(path)
    pipeline = DrivePipeline(model, DriveConfig(monitor=MonitorPolicy(MonitorMode.WARN, budget_ms=None)))
    monitor = pipeline.client_monitor("t")
    for frame in FRAMES[:4]:
        x = preprocess(decode_image(frame.payload()["image"], reduce=pipeline.reduce), model.contract)
        want = float(np.asarray(session.run(None, {session.get_inputs()[0].name: x})[0]).reshape(-1)[0])
        pipeline.run(parse_telemetry(frame.payload()), None, monitor)
        assert monitor.last is not None and monitor.last.score == want


def test_the_bundled_generalist_carries_mcdropout_and_the_server_scores_it_with_the_networks_steering():
    """generalist.onnx's monitor is the benchmarked one: MC-dropout (four masked copies of its network in the graph)
    beside the frame statistics, calibrated on more than an hour of nominal laps of training worlds; drive_server's
    score is that graph's answer on the frame and the served network's own steering (before smoothing); its
    steering is the network's as without a monitor."""
    meta = {p.key: p.value for p in onnx.load(str(GENERALIST)).metadata_props}
    spec, graph = SteeringModel(GENERALIST).monitor()
    assert spec.score == "mcdropout+framestats" and spec.inputs == (FRAME, STEERING) and graph.wants_steering
    calibration = json.loads(meta[MONITOR_KEY])["calibration"]
    assert calibration["samples"] == 4 and [p["score"] for p in calibration["parts"]] == ["mcdropout", "framestats"]
    assert calibration["hours"] >= 1.0 and 0 < spec.warn <= spec.alarm
    session = ort.InferenceSession(base64.b64decode(meta["rbc.monitor.onnx"]), providers=["CPUExecutionProvider"])
    names = [i.name for i in session.get_inputs()]
    model = SteeringModel(GENERALIST)
    pipeline = DrivePipeline(model, DriveConfig(monitor=MonitorPolicy(MonitorMode.WARN, budget_ms=None)))
    plain = DrivePipeline(model, DriveConfig())
    monitor, smoother, smoother_plain = pipeline.client_monitor("t"), pipeline.smoother(), plain.smoother()
    for frame in FRAMES[:4]:
        x = preprocess(decode_image(frame.payload()["image"], reduce=pipeline.reduce), model.contract)
        steering = np.array([[model.predict(x)]], np.float32)  # (batch, 1)
        want = float(np.asarray(session.run(None, {names[0]: x, names[1]: steering})[0]).reshape(-1)[0])
        sent = pipeline.run(parse_telemetry(frame.payload()), smoother, monitor)[0].steering
        assert monitor.last is not None and monitor.last.score == pytest.approx(want, abs=1e-6)
        assert sent == plain.run(parse_telemetry(frame.payload()), smoother_plain, None)[0].steering


def test_the_demo_model_carries_the_camera_check_beside_its_autoencoder():
    """generalist_pilotnet.onnx (rbc demo's model): the autoencoder and the frame statistics, each in units of its own
    alarm threshold, calibrated on more than an hour of nominal laps; a washed-out frame scores above the frame."""
    path = PRETRAINED / "generalist_pilotnet.onnx"
    spec, graph = SteeringModel(path).monitor()
    calibration = spec.calibration
    assert spec.score == "autoencoder+framestats" and spec.inputs == (FRAME,)
    assert [p["score"] for p in calibration["parts"]] == ["autoencoder", "framestats"]
    assert calibration["hours"] >= 1.0 and 0 < spec.warn <= spec.alarm
    model = SteeringModel(path)
    rgb = decode_image(FRAMES[0].payload()["image"], reduce=1)
    washed = np.clip(rgb.astype(np.float32) * 6, 0, 255).astype(np.uint8)
    scores = [graph.score(preprocess(img, model.contract)) for img in (rgb, washed)]
    assert scores[1] > max(1.0, 2 * scores[0])
