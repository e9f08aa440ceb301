"""#52: the steering gain is a serving setting (``rbc.serving``), applied the same way by every closed loop, and
left out of the open-loop figures; files that carry it inside their graph keep serving as they did."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from drive_server.serving.model import ModelError, SteeringModel
from drive_server.serving.pipeline import DriveConfig, DrivePipeline
from drive_server.serving.settings import SERVING_KEY, Serving, serving_json
from models.onnxfiles.gain_onnx import GainError, move_gain_to_serving
from protocol.errors import BadValue

REPO = Path(__file__).resolve().parents[1]
UNITY = REPO / "models" / "pretrained" / "unity.onnx"
SAMPLE = REPO / "tests" / "data" / "udacity-sample"


def _with_serving(src: Path, dst: Path, value: str | None, extra: dict | None = None) -> Path:
    import onnx

    proto = onnx.load(str(src))
    meta = {p.key: p.value for p in proto.metadata_props if p.key != SERVING_KEY}
    if value is not None:
        meta[SERVING_KEY] = value
    if extra is not None:
        meta["rbc.model"] = json.dumps({**json.loads(meta.get("rbc.model", "{}")), **extra})
    del proto.metadata_props[:]
    for k, v in meta.items():
        proto.metadata_props.add(key=k, value=v)
    onnx.save(proto, str(dst))
    return dst


def _frames(n: int = 12) -> list[np.ndarray]:
    from PIL import Image

    return [np.asarray(Image.open(p).convert("RGB")) for p in sorted((SAMPLE / "IMG").glob("center*.jpg"))[:n]]


def test_serving_metadata_reads_both_settings_and_refuses_bad_ones_in_one_line() -> None:
    assert Serving.from_json(None) == Serving() and not Serving().asks_anything
    assert Serving.from_json('{"gain": 1.5, "smoothing": 0.5}') == Serving(0.5, 1.5)
    assert Serving.from_json('{"smooth": 0.5}') == Serving(0.5, 1.0)  # files written before the one name
    assert json.loads(serving_json(0.5, 1.5)) == {"gain": 1.5, "smoothing": 0.5}
    assert json.loads(serving_json(0.5)) == {"smoothing": 0.5}  # a reader without the gain still reads it
    assert Serving(0.5, 1.5).describe() == "steering x1.5, smoothed (alpha 0.5)"
    for bad, says in [('{"gain": 0}', "steering gain"), ('{"gain": 3}', "steering gain"), ('{"gain": "x"}', "gain"),
                      ('{"gain": true}', "gain"), ('{"speed": 1}', "at most the keys"), ("[1]", "at most the keys"),
                      ('{"gain": NaN}', "steering gain")]:
        with pytest.raises(BadValue, match=says) as info:
            Serving.from_json(bad)
        assert "\n" not in str(info.value)


def test_a_model_file_that_asks_for_a_bad_gain_is_refused_at_load(tmp_path: Path) -> None:
    bad = _with_serving(UNITY, tmp_path / "bad.onnx", '{"gain": 5}')
    with pytest.raises(ModelError, match="bad.onnx: steering gain must be 0.1..2") as info:
        SteeringModel(bad)
    assert "\n" not in str(info.value)


def test_the_pipeline_multiplies_clamps_then_smooths_and_a_config_overrides_the_files_gain(tmp_path: Path) -> None:
    network = DrivePipeline(SteeringModel(UNITY), DriveConfig(gain=1.0, smoothing=1.0))
    served = DrivePipeline(SteeringModel(UNITY), DriveConfig(smoothing=1.0))
    assert served.gain == 1.5 and network.gain == 1.0
    for frame in _frames():
        raw = network.steer(frame)
        assert served.steer(frame) == pytest.approx(max(-1.0, min(1.0, 1.5 * raw)), abs=1e-6)
    strong = DrivePipeline(SteeringModel(UNITY), DriveConfig(gain=2.0, smoothing=1.0))
    frame = _frames(1)[0]
    assert strong.steer(frame) == pytest.approx(max(-1.0, min(1.0, 2.0 * network.steer(frame))), abs=1e-6)
    plain = _with_serving(UNITY, tmp_path / "plain.onnx", None)  # no rbc.serving: the network as it answers
    assert DrivePipeline(SteeringModel(plain)).gain == 1.0 and DrivePipeline(SteeringModel(plain)).smoothing == 1.0
    with pytest.raises(BadValue, match="steering gain"):
        DriveConfig(gain=0.0)


def test_moving_a_baked_gain_into_serving_metadata_serves_the_same_steering(tmp_path: Path) -> None:
    """An older file ends in Mul(network, S) and records output_scale S: served as it is, it steers as the
    rewritten file (network graph + gain S in rbc.serving) does; the rewritten graph answers the network."""
    import onnx
    from onnx import helper, numpy_helper

    proto = onnx.load(str(UNITY))  # the network alone, to bake a gain into, as older exports did
    out = proto.graph.output[0].name
    proto.graph.node[-1].output[0] = "net_out"
    proto.graph.initializer.append(numpy_helper.from_array(np.array(1.5, np.float32), "scale"))
    proto.graph.node.append(helper.make_node("Mul", ["net_out", "scale"], [out]))
    onnx.save(proto, str(tmp_path / "tmp.onnx"))
    baked = _with_serving(tmp_path / "tmp.onnx", tmp_path / "baked.onnx", '{"smoothing": 0.5}',
                          {"output_scale": 1.5, "gain": 1.0})
    moved = tmp_path / "moved.onnx"
    assert move_gain_to_serving(baked, moved) < 1e-5
    a, b = DrivePipeline(SteeringModel(baked)), DrivePipeline(SteeringModel(moved))
    assert (a.gain, b.gain, b.smoothing) == (1.0, 1.5, 0.5)
    sa, sb = a.smoother(), b.smoother()
    assert max(abs(a.steer(f, sa) - b.steer(f, sb)) for f in _frames()) < 1e-6
    info = json.loads(SteeringModel(moved)._session.get_modelmeta().custom_metadata_map["rbc.model"])
    assert info["gain"] == 1.5 and "output_scale" not in info
    with pytest.raises(GainError, match="no recorded output scale"):
        move_gain_to_serving(moved, tmp_path / "again.onnx")


def test_drive_server_says_the_gain_at_start_up_and_refuses_a_bad_flag_in_one_line(capsys) -> None:
    from drive_server.cli import main

    assert main(["--gain", "7", "--port", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("drive_server: error: steering gain must be 0.1..2") and "\n" not in err
    assert "steering x1.5, smoothed (alpha 0.5)" in SteeringModel(UNITY).describe()


def test_the_open_loop_score_is_the_networks_prediction_without_the_gain() -> None:
    from protocol.datalog import read_log
    from protocol.jpeg import read_jpeg_file
    from tools.evaluate.offline import camera_frames, score_models

    samples, _ = read_log(SAMPLE)
    frames = camera_frames(samples, "center")
    (score,) = score_models([UNITY], SAMPLE)
    network = DrivePipeline(SteeringModel(UNITY), DriveConfig(gain=1.0))
    smoother = network.smoother()
    pred = np.array([network.steer(read_jpeg_file(p, reduce=network.reduce), smoother) for p, _ in frames])
    truth = np.array([s for _, s in frames])
    assert score.mse == pytest.approx(float(np.mean((pred - truth) ** 2)), rel=1e-6)
