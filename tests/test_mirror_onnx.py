"""``rbc mirror`` / ``models.onnxfiles.mirror_onnx``: an existing ONNX model made to answer (f(x) - f(mirror x)) / 2,
checked against the original, its contract kept, bad files refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers_server import build_shallow

from drive_server.serving.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY
from drive_server.serving.model import SteeringModel
from tools.cli import main as rbc

ort = pytest.importorskip("onnxruntime")
pytest.importorskip("onnx", reason="mirroring rewrites the ONNX graph")


def _run(path: Path, x: np.ndarray) -> np.ndarray:
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return session.run(None, {session.get_inputs()[0].name: x})[0].ravel()


@pytest.mark.parametrize(("layout", "width_axis"), [("nhwc", 2), ("nchw", 3)])
def test_the_mirrored_model_is_half_the_difference_of_the_original_on_a_frame_and_its_mirror(
        tmp_path: Path, layout: str, width_axis: int) -> None:
    original = build_shallow(tmp_path / f"{layout}.onnx", seed=5, layout=layout)
    out = tmp_path / f"{layout}_mirror.onnx"
    assert rbc(["mirror", str(original), "--out", str(out), "--serve-smooth", "0.5"]) == 0
    shape = SteeringModel(original).contract.input_shape[1:]
    x = np.random.default_rng(1).random((6, *shape), dtype=np.float32) - 0.5
    flipped = np.ascontiguousarray(np.flip(x, axis=width_axis))
    plain, plain_flipped = _run(original, x), _run(original, flipped)
    assert np.abs(plain + plain_flipped).max() > 1e-3  # the random network alone leans: the check means something
    got = _run(out, x)
    assert np.allclose(got, 0.5 * (plain - plain_flipped), atol=1e-5)
    assert np.allclose(_run(out, flipped), -got, atol=1e-6)
    assert np.allclose([_run(out, x[i:i + 1])[0] for i in range(len(x))], got, atol=1e-6)  # batch of 1 too
    served = SteeringModel(out)
    assert served.contract == SteeringModel(original).contract and served.smoothing == 0.5
    import onnxruntime

    meta = onnxruntime.InferenceSession(str(out)).get_modelmeta().custom_metadata_map
    info = json.loads(meta[METADATA_MODEL_INFO_KEY])
    assert info["mirror_average"] is True and info["smoothing"] == 0.5 and METADATA_KEY in meta
    assert "serve_smooth" not in info  # the one name


def test_bad_models_and_paths_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    original = build_shallow(tmp_path / "m.onnx", seed=2)
    mirrored = tmp_path / "mm.onnx"
    assert rbc(["mirror", str(original), "--out", str(mirrored)]) == 0
    not_onnx = tmp_path / "x.onnx"
    not_onnx.write_bytes(b"not a model")
    cases = [([str(mirrored), "--out", str(tmp_path / "again.onnx")], "already mirror-averaged"),
             ([str(not_onnx), "--out", str(tmp_path / "y.onnx")], "not an ONNX model"),
             ([str(tmp_path / "missing.onnx"), "--out", str(tmp_path / "z.onnx")], "no model at"),
             ([str(original), "--out", str(original)], "must not be the model itself"),
             ([str(original), "--out", str(tmp_path / "w.onnx"), "--serve-smooth", "0"], "above 0"),
             ([str(original), "--out", str(tmp_path / "v.onnx"), "--gain", "3"], "steering gain must be 0.1..2")]
    capsys.readouterr()
    for argv, says in cases:
        assert rbc(["mirror", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("rbc mirror: error") and says in err and "\n" not in err, err
    assert not (tmp_path / "again.onnx").exists() and not (tmp_path / "y.onnx").exists()
    assert not (tmp_path / "v.onnx").exists()


def test_a_model_trained_elsewhere_is_mirrored_with_a_serving_gain_as_rbc_train_would_export_it(
        tmp_path: Path) -> None:
    """``--gain G``: the graph answers (f(x) - f(mirror x)) / 2 and the file asks drive_server for G, as a recipe's
    ``[export] gain``; served through the pipeline, the answer is G times the average (the old ``--output-scale``
    spelling gives the same file). A gain the source asks for is kept."""
    from drive_server.serving.pipeline import DriveConfig, DrivePipeline

    original = build_shallow(tmp_path / "m.onnx", seed=3)
    plain, gained, old = tmp_path / "plain.onnx", tmp_path / "gained.onnx", tmp_path / "old.onnx"
    assert rbc(["mirror", str(original), "--out", str(plain)]) == 0
    assert rbc(["mirror", str(original), "--out", str(gained), "--gain", "0.8"]) == 0
    assert rbc(["mirror", str(original), "--out", str(old), "--output-scale", "0.8"]) == 0
    x = np.random.default_rng(2).random((5, *SteeringModel(original).contract.input_shape[1:]), dtype=np.float32)
    assert np.allclose(_run(gained, x - 0.5), _run(plain, x - 0.5), atol=1e-6)  # the graph is the network's
    assert SteeringModel(gained).gain == SteeringModel(old).gain == pytest.approx(0.8)
    assert SteeringModel(plain).gain == 1.0
    frame = np.random.default_rng(5).integers(0, 255, (160, 320, 3), dtype=np.uint8)
    served, network = DrivePipeline(SteeringModel(gained)), DrivePipeline(SteeringModel(gained), DriveConfig(gain=1.0))
    assert served.steer(frame) == pytest.approx(max(-1.0, min(1.0, 0.8 * network.steer(frame))), abs=1e-6)
    import onnxruntime

    info = json.loads(onnxruntime.InferenceSession(str(gained)).get_modelmeta().custom_metadata_map[
        METADATA_MODEL_INFO_KEY])
    assert info["gain"] == pytest.approx(0.8) and info["mirror_average"] is True and "output_scale" not in info


def test_a_lane_keeping_model_is_not_mirrored_nor_trained_mirrored(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Keeping to the right lane is left-right asymmetric: the average would steer to the road's middle (the
    mirrored generalist crossed the mountain's centre line 8 times a lap where the plain one crossed it once)."""
    import onnx

    from models.onnxfiles.onnx_metadata import set_model_metadata

    model = build_shallow(tmp_path / "rigorous.onnx", seed=4)
    proto = onnx.load(str(model))
    set_model_metadata(proto, {"behavior": "rigorous"})
    onnx.save(proto, str(model))
    capsys.readouterr()
    assert rbc(["mirror", str(model), "--out", str(tmp_path / "m.onnx")]) == 2
    err = capsys.readouterr().err.strip()
    assert "keeps to one lane" in err and "\n" not in err and not (tmp_path / "m.onnx").exists()
    recipe = tmp_path / "rigorous-mirrored.toml"
    recipe.write_text('[network]\nbehavior = "rigorous"\n\n[export]\nmirror_average = true\n')
    assert rbc(["train", "--recipe", str(recipe), "--data", str(tmp_path), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert "keeps to one lane" in err and "\n" not in err and not (tmp_path / "run").exists()
