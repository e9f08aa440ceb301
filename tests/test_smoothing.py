"""Steering smoothed over time (``drive_server --smooth``, and ``--smooth`` of rbc score, drive-log and data
crossval): one client's state only, the same arithmetic everywhere, bad values refused in one line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from helpers_server import SAMPLE_LOG, build_shallow, run_server_cli

from drive_server.serving.model import ModelError, SteeringModel
from drive_server.serving.models_dir import default_model_path
from drive_server.serving.pipeline import DriveConfig, DrivePipeline
from drive_server.serving.settings import SERVING_KEY, serving_json
from drive_server.serving.smoothing import SteeringSmoother, check_alpha
from protocol import parse_telemetry
from tools.cli import main as rbc

pytest.importorskip("onnx", reason="the tests build their ONNX model with the onnx package")


def test_each_command_is_alpha_of_the_new_output_and_the_rest_of_the_last() -> None:
    s = SteeringSmoother(0.25)
    assert s(0.8) == pytest.approx(0.8)  # a new client starts from its first output
    assert s(0.0) == pytest.approx(0.6)
    assert s(-0.4) == pytest.approx(0.25 * -0.4 + 0.75 * 0.6)
    off = SteeringSmoother(1.0)
    assert [off(v) for v in (0.3, -0.9, 0.1)] == [0.3, -0.9, 0.1]
    assert DriveConfig().smoothing is None  # the model's own


@pytest.mark.parametrize("alpha", [0.0, -0.5, 1.5, math.nan, math.inf])
def test_a_weight_outside_0_to_1_is_refused(alpha: float) -> None:
    with pytest.raises(ValueError, match="above 0 and at most 1"):
        check_alpha(alpha)
    with pytest.raises(ValueError):
        DriveConfig(smoothing=alpha)


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    return build_shallow(tmp_path_factory.mktemp("model") / "tiny.onnx", seed=3)


def _frames_with_different_steering(model: Path) -> tuple[list, list[float]]:
    from tools.wire.frames import log_frames

    pipeline = DrivePipeline(SteeringModel(model))
    frames = log_frames(SAMPLE_LOG)
    steer = [pipeline.run(parse_telemetry(f.payload()))[0].steering for f in frames[:40]]
    i = int(np.argmax(np.abs(np.array(steer) - steer[0])))
    assert abs(steer[i] - steer[0]) > 1e-3, "the tiny model answers every frame alike: the test would mean nothing"
    return [frames[0].payload(), frames[i].payload()], [steer[0], steer[i]]


def _with_serving(model: Path, out: Path, value: str) -> Path:
    import onnx

    proto = onnx.load(str(model))
    proto.metadata_props.add(key=SERVING_KEY, value=value)
    onnx.save(proto, str(out))
    return out


def test_a_model_carries_its_smoothing_and_a_flag_overrides_it(model: Path, tmp_path: Path) -> None:
    asks = _with_serving(model, tmp_path / "asks.onnx", serving_json(0.5))
    assert DrivePipeline(SteeringModel(model)).smoother() is None  # no metadata: off
    assert DrivePipeline(SteeringModel(asks)).smoothing == 0.5
    assert DrivePipeline(SteeringModel(asks), DriveConfig(smoothing=1.0)).smoother() is None
    assert DrivePipeline(SteeringModel(model), DriveConfig(smoothing=0.3)).smoothing == 0.3
    assert "smoothed (alpha 0.5)" in SteeringModel(asks).describe()


def test_the_smoothing_has_one_name_and_files_written_before_it_still_read(model: Path, tmp_path: Path) -> None:
    """Issue 51: the value was serve_smoothing (recipe), serve_smooth (record), smooth (metadata JSON)."""
    assert json.loads(serving_json(0.5)) == {"smoothing": 0.5}
    old = _with_serving(model, tmp_path / "old.onnx", '{"smooth": 0.25}')  # as every model written before
    assert SteeringModel(old).smoothing == 0.25
    for bundled in ("unity", "generalist"):  # both written before the one name, both ask for 0.5
        assert SteeringModel(default_model_path().with_name(f"{bundled}.onnx")).smoothing == 0.5


@pytest.mark.parametrize("value", ['{"smooth": 0}', '{"smooth": "half"}', "[0.5]", '{"smooth": 0.5, "x": 1}', "{",
                                   '{"smoothing": 0}', '{"smoothing": 0.5, "smooth": 0.5}'])
def test_a_malformed_serving_entry_is_one_line(model: Path, tmp_path: Path, value: str) -> None:
    bad = _with_serving(model, tmp_path / "bad.onnx", value)
    with pytest.raises(ModelError, match=f"bad.onnx: .*{SERVING_KEY}|bad.onnx: steering smoothing") as info:
        SteeringModel(bad)
    assert "\n" not in str(info.value)
    done = run_server_cli("--model", str(bad), "--port", "0")
    assert done.returncode == 2 and done.stderr.strip().startswith("drive_server: error: bad.onnx")


@pytest.mark.slow
def test_drive_server_smooths_each_client_on_its_own(model: Path) -> None:
    from tools.wire.server_process import ServerProcess
    from tools.wire.unity_client import UnityWireClient

    (first, second), (s0, s1) = _frames_with_different_steering(model)
    with ServerProcess(model, ["--log-every", "0", "--smooth", "0.5"]) as server, \
            UnityWireClient(server.url) as a, UnityWireClient(server.url) as b:
        assert a.exchange(first)[0].steering == pytest.approx(s0, abs=2e-6)
        assert b.exchange(second)[0].steering == pytest.approx(s1, abs=2e-6)  # b: its own first
        assert a.exchange(second)[0].steering == pytest.approx(0.5 * s1 + 0.5 * s0, abs=2e-6)
        assert b.exchange(second)[0].steering == pytest.approx(s1, abs=2e-6)  # a's frames left b alone
    assert "steering smoothed per client (alpha 0.5, --smooth)" in server.log()


def test_drive_server_refuses_a_bad_smoothing_weight_in_one_line(model: Path) -> None:
    done = run_server_cli("--model", str(model), "--smooth", "0", "--port", "0")
    assert done.returncode == 2
    err = done.stderr.strip()
    assert err.startswith("drive_server: error") and "smoothing" in err and "\n" not in err


def test_rbc_score_smooths_the_predictions_in_log_order(model: Path, tmp_path: Path) -> None:
    plain, smooth = tmp_path / "plain.json", tmp_path / "smooth.json"
    assert rbc(["score", "--data", str(SAMPLE_LOG), "--model", str(model), "--json", str(plain)]) == 0
    assert rbc(["score", "--data", str(SAMPLE_LOG), "--model", str(model), "--smooth", "0.3",
                "--json", str(smooth)]) == 0
    a, b = (json.loads(p.read_text()) for p in (plain, smooth))
    assert b["smooth"] == 0.3 and b["scores"][0]["smooth"] == 0.3 and a["scores"][0]["smooth"] == 1.0
    assert a["scores"][0]["mse"] != pytest.approx(b["scores"][0]["mse"], rel=1e-9)


@pytest.mark.parametrize("argv", [
    ["score", "--data", str(SAMPLE_LOG), "--smooth", "2"],
    ["drive-log", "--data", str(SAMPLE_LOG), "--baseline", "zero", "--smooth", "0.5"],
    ["drive-log", "--data", str(SAMPLE_LOG), "--model", "x.onnx", "--smooth", "nan"],
    ["data", "crossval", "--models", "runs/cv-{fold}/model.onnx", "--smooth", "0"],
])
def test_rbc_refuses_bad_smoothing_in_one_line(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert rbc(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("rbc ") and "smooth" in err and "\n" not in err and "Traceback" not in err
