"""The exported model is the best epoch's (or the last, on request), and a crop travels in the contract so
drive_server feeds the network exactly the pixels training did."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
ort = pytest.importorskip("onnxruntime")

from drive_server.serving.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY, PreprocessContract  # noqa: E402
from drive_server.serving.model import SteeringModel  # noqa: E402
from drive_server.serving.pipeline import DriveConfig, DrivePipeline  # noqa: E402
from drive_server.serving.preprocess import to_input_tensor  # noqa: E402
from models.data.framecache import build_cache, load_frame  # noqa: E402
from models.networks.nets import ContractInput, build_model  # noqa: E402
from models.training import train as train_mod  # noqa: E402
from models.training.train import TrainConfig, train  # noqa: E402
from protocol.datalog import read_log  # noqa: E402

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
pytestmark = pytest.mark.slow


def _config(out: Path, **kw) -> TrainConfig:
    base = dict(data=[str(SAMPLE)], out=str(out), epochs=3, max_steps_per_epoch=2, threads=1, decode_workers=1,
                progress=False, seed=4)
    return TrainConfig(**{**base, **kw})


def _onnx_outputs(path: Path, x: np.ndarray) -> np.ndarray:
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return session.run(None, {session.get_inputs()[0].name: x})[0]


def _torch_outputs(state: dict, x: np.ndarray) -> np.ndarray:
    net = build_model("shallow", 64, 64)
    net.load_state_dict(state)
    with torch.no_grad():
        return ContractInput(net, "nhwc").eval()(torch.from_numpy(x)).numpy()


@pytest.mark.parametrize(("export", "epoch"), [("best", 2), ("last", 3)])
def test_the_exported_model_is_the_best_epoch(tmp_path: Path, monkeypatch, export: str, epoch: int) -> None:
    losses = iter([0.30, 0.10, 0.20])  # epoch 2 is the best; the run ends worse
    monkeypatch.setattr(train_mod, "evaluate", lambda *a, **k: next(losses))
    result = train(_config(tmp_path / export, export=export))
    record = json.loads((result.run_dir / "config.json").read_text())
    assert record["result"]["exported_epoch"] == epoch and record["result"]["export"] == export
    assert result.val_loss == pytest.approx([0.30, 0.10, 0.20][epoch - 1])
    assert record["result"]["last_epoch_val_mse"] == pytest.approx(0.20)
    meta = json.loads(ort.InferenceSession(str(result.onnx)).get_modelmeta().custom_metadata_map[
        METADATA_MODEL_INFO_KEY])
    assert meta["exported_epoch"] == epoch and meta["val_mse"] == pytest.approx(result.val_loss)
    checkpoint = torch.load(result.run_dir / "checkpoint.pt", weights_only=False)
    samples, _ = read_log(SAMPLE)
    x = to_input_tensor(build_cache(samples[:8], PreprocessContract(), ("center",), workers=1).frames[0],
                        PreprocessContract())
    got = _onnx_outputs(result.onnx, x)
    best, last = _torch_outputs(checkpoint["best_model"], x), _torch_outputs(checkpoint["model"], x)
    assert not np.allclose(best, last, atol=1e-4)  # the two candidates differ, so the check below means something
    assert np.abs(got - (best if export == "best" else last)).max() < 1e-4


def test_crop_is_carried_through_the_contract_and_served_identically(tmp_path: Path) -> None:
    result = train(_config(tmp_path / "crop", epochs=1, max_steps_per_epoch=1, crop_top=64, crop_bottom=136))
    session = ort.InferenceSession(str(result.onnx), providers=["CPUExecutionProvider"])
    contract = PreprocessContract.from_json(session.get_modelmeta().custom_metadata_map[METADATA_KEY])
    assert (contract.crop_top, contract.crop_bottom) == (64, 136)
    record = json.loads((result.run_dir / "config.json").read_text())
    assert record["contract"]["crop_top"] == 64 and record["config"]["crop_bottom"] == 136
    model = SteeringModel(result.onnx)
    assert model.contract == contract
    pipeline = DrivePipeline(model)
    samples, _ = read_log(SAMPLE)
    trained_on = build_cache(samples[:5], contract, ("center",), workers=1).frames[0]  # what training fed the net
    for i, s in enumerate(samples[:5]):
        rgb = load_frame(s.center, pipeline.reduce)  # what drive_server decodes from the wire
        served = float(_onnx_outputs(result.onnx, to_input_tensor(trained_on[i], contract))[0, 0])
        assert pipeline.steer(rgb) == pytest.approx(max(-1.0, min(1.0, served)), abs=1e-6)
    # and the crop matters: the same frames uncropped give other inputs
    full = build_cache(samples[:1], PreprocessContract(), ("center",), workers=1).frames[0]
    assert np.abs(full.astype(int) - trained_on[:1]).mean() > 5


def _frames_and_network_outputs(result) -> tuple[np.ndarray, ...]:
    """Eight sample frames, their mirror images, and the trained network's (checkpoint's) answers to both."""
    checkpoint = torch.load(result.run_dir / "checkpoint.pt", weights_only=False)
    samples, _ = read_log(SAMPLE)
    x = to_input_tensor(build_cache(samples[:8], PreprocessContract(), ("center",), workers=1).frames[0],
                        PreprocessContract())
    mirrored = np.ascontiguousarray(x[:, :, ::-1])  # NHWC: the width axis
    return x, mirrored, _torch_outputs(checkpoint["model"], x), _torch_outputs(checkpoint["model"], mirrored)


def test_mirror_average_and_smoothing_are_exported_and_recorded(tmp_path: Path) -> None:
    result = train(_config(tmp_path / "mirror", epochs=1, max_steps_per_epoch=2, export="last", mirror_average=True,
                           smoothing=0.5))
    x, mirrored, plain, plain_mirrored = _frames_and_network_outputs(result)
    assert np.abs(plain + plain_mirrored).max() > 1e-3  # the trained network alone is not symmetric
    got, got_mirrored = _onnx_outputs(result.onnx, x), _onnx_outputs(result.onnx, mirrored)
    assert np.abs(got - 0.5 * (plain - plain_mirrored)).max() < 1e-4
    assert np.abs(got + got_mirrored).max() < 1e-5  # a mirrored road: exactly the opposite steering
    meta = json.loads(ort.InferenceSession(str(result.onnx)).get_modelmeta().custom_metadata_map[
        METADATA_MODEL_INFO_KEY])
    record = json.loads((result.run_dir / "config.json").read_text())
    assert meta["mirror_average"] is True and record["config"]["mirror_average"] is True
    assert SteeringModel(result.onnx).smoothing == 0.5 and record["config"]["smoothing"] == meta["smoothing"] == 0.5
    assert record["recipe"]["export"] == meta["recipe"]["export"] == {"mirror_average": True, "gain": 1.0,
                                                                      "smoothing": 0.5}


def test_the_gain_is_a_serving_setting_the_network_and_its_validation_figures_are_without_it(tmp_path: Path) -> None:
    """#52: the recipe's gain goes into the file's serving metadata, not the graph: the ONNX output and the run's
    validation figures are the network's own prediction of the driver; drive_server's pipeline multiplies it."""
    config = dict(epochs=1, max_steps_per_epoch=2, export="last", mirror_average=True)
    result = train(_config(tmp_path / "gained", **config, gain=1.5))
    plain = train(_config(tmp_path / "plain", **config))
    x, mirrored, net, net_mirrored = _frames_and_network_outputs(result)
    assert np.abs(_onnx_outputs(result.onnx, x) - 0.5 * (net - net_mirrored)).max() < 1e-4  # no gain in the graph
    assert np.allclose(_onnx_outputs(result.onnx, x), _onnx_outputs(plain.onnx, x), atol=1e-6)
    assert json.dumps(result.info["metrics"]) == json.dumps(plain.info["metrics"])  # open loop: the network's
    meta = ort.InferenceSession(str(result.onnx)).get_modelmeta().custom_metadata_map
    record = json.loads((result.run_dir / "config.json").read_text())
    assert json.loads(meta["rbc.serving"]) == {"gain": 1.5}
    assert json.loads(meta[METADATA_MODEL_INFO_KEY])["gain"] == 1.5 and record["config"]["gain"] == 1.5
    frame = np.random.default_rng(1).integers(0, 255, (160, 320, 3), dtype=np.uint8)
    served = DrivePipeline(SteeringModel(result.onnx)).steer(frame)
    network = DrivePipeline(SteeringModel(result.onnx), DriveConfig(gain=1.0)).steer(frame)
    assert served == pytest.approx(max(-1.0, min(1.0, 1.5 * network)), abs=1e-6)
    with pytest.raises(ValueError, match=r"gain must be 0.1..2, got 0.0"):
        _config(tmp_path / "bad", gain=0.0)
    old = json.loads((plain.run_dir / "config.json").read_text())["config"]
    del old["gain"]
    old["output_scale"] = 1.2  # a run stored when the gain was multiplied into the graph
    assert TrainConfig.from_dict(old).gain == 1.2


def test_inspect_scores_validation_frames_only_and_says_so(tmp_path: Path, capsys) -> None:
    pytest.importorskip("matplotlib")
    from models.data.trainingdata import prepare_data
    from models.training.metrics import steering_metrics
    from tools.cli import main

    config = _config(tmp_path / "run", epochs=1, max_steps_per_epoch=2)
    result = train(config)
    capsys.readouterr()
    assert main(["inspect", str(result.run_dir), "--frames", "20", "--samples", "1"]) == 0
    out = capsys.readouterr().out
    stored = TrainConfig.from_dict(json.loads((result.run_dir / "config.json").read_text())["config"])
    data = prepare_data(stored.data, stored.pipeline(), stored.seed, stored.data_options(), workers=1)
    window = data.usable[:20]
    val = window[np.isin(window, data.val)]
    assert 0 < len(val) < len(window)  # the plotted window holds training frames too: they must not count
    x = to_input_tensor(data.cache.frames[0, val], stored.pipeline().contract)
    expected = steering_metrics(_onnx_outputs(result.onnx, x).ravel(), data.steering[val])
    line = next(ln for ln in out.splitlines() if ln.startswith("held-out frames in the plotted window: "))
    assert f"({len(val)} frames)" in line
    assert f"MSE {expected['mse']:.4f}" in line
    assert "all held-out frames: " in out
    assert str(result.run_dir / "inspect" / "predictions.png") in out.splitlines()  # into RUN/inspect/
