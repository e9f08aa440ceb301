"""Preprocessing driven by the model: contract in ONNX metadata, defaults inferred from the input shape."""

from __future__ import annotations

import logging
from dataclasses import replace

import cv2
import numpy as np
import pytest
from helpers_server import SAMPLE_LOG

from drive_server.serving.contract import (
    METADATA_KEY,
    NVIDIA_CONTRACT,
    PAPER_CONTRACT,
    ContractError,
    PreprocessContract,
    infer_contract,
)
from drive_server.serving.preprocess import frame_to_network_image, jpeg_reduction, preprocess, to_input_tensor

onnx = pytest.importorskip("onnx", reason="the tests build their ONNX models with the onnx package")

from drive_server.serving.model import ModelError, SteeringModel  # noqa: E402
from models.networks.architectures import PILOTNET, SHALLOW  # noqa: E402
from tools.bench.onnx_builders import build_model, save_model  # noqa: E402

FRAME = cv2.cvtColor(cv2.imread(str(next((SAMPLE_LOG / "IMG").glob("center_*.jpg")))), cv2.COLOR_BGR2RGB)


def test_contract_json_round_trip():
    c = replace(NVIDIA_CONTRACT, interpolation="linear")
    assert PreprocessContract.from_json(c.to_json()) == c
    with pytest.raises(ContractError):
        PreprocessContract.from_json('{"width": 64, "bogus": 1}')
    with pytest.raises(ContractError):
        PreprocessContract.from_json("not json")


def test_contract_read_from_onnx_metadata(tmp_path):
    contract = PreprocessContract(width=200, height=66, crop_top=60, crop_bottom=160, color="yuv", offset=0.0)
    path = save_model(PILOTNET, tmp_path / "p.onnx", contract=contract)
    model = SteeringModel(path)
    assert model.contract == contract and model.contract_source == "metadata"
    assert dict((p.key, p.value) for p in onnx.load(str(path)).metadata_props)[METADATA_KEY] == contract.to_json()


@pytest.mark.parametrize("layout", ["nhwc", "nchw"])
def test_default_contract_inferred_from_input_shape(tmp_path, caplog, layout):
    path = save_model(SHALLOW, tmp_path / f"{layout}.onnx", with_metadata=False, layout=layout)
    with caplog.at_level(logging.INFO):
        model = SteeringModel(path)
    assert model.contract == replace(PAPER_CONTRACT, layout=layout) and model.contract_source == "inferred"
    assert any(METADATA_KEY in r.getMessage() and "assuming" in r.getMessage() for r in caplog.records)
    model.warm_up()
    x = preprocess(FRAME, model.contract)
    assert x.shape == model.contract.input_shape and x.dtype == np.float32
    assert np.isfinite(model.predict(x))  # the graph really takes this layout


def test_infer_contract_rejects_non_images():
    for shape in [(1, 64, 64), (1, 64, 64, 4), (1, 5, 64, 64), (1, "h", "w", 3)]:
        with pytest.raises(ContractError):
            infer_contract(shape)


def test_contract_that_does_not_match_the_input_is_refused(tmp_path):
    model = build_model(SHALLOW)
    wrong = replace(PAPER_CONTRACT, width=200, height=66)
    onnx.helper.set_model_props(model, {METADATA_KEY: wrong.to_json()})
    path = tmp_path / "wrong.onnx"
    path.write_bytes(model.SerializeToString())
    with pytest.raises(ModelError, match="expects input"):
        SteeringModel(path)


def test_paper_preprocessing_values():
    x = preprocess(FRAME, PAPER_CONTRACT)
    assert x.shape == (1, 64, 64, 3)
    expected = cv2.resize(FRAME, (64, 64), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0 - 0.5
    np.testing.assert_allclose(x[0], expected, atol=1e-6)
    assert x.min() >= -0.5 and x.max() <= 0.5


def test_yuv_crop_path_of_nvidia_contract():
    img = frame_to_network_image(FRAME, NVIDIA_CONTRACT)
    expected = cv2.cvtColor(cv2.resize(FRAME[60:160], (200, 66), interpolation=cv2.INTER_AREA), cv2.COLOR_RGB2YUV)
    np.testing.assert_array_equal(img, expected)
    x = to_input_tensor(img, replace(NVIDIA_CONTRACT, layout="nchw"))
    assert x.shape == (1, 3, 66, 200)
    np.testing.assert_allclose(x[0, 0], expected[..., 0] / 255.0, atol=1e-6)  # Y plane first, x/255


def test_a_contract_can_ask_for_a_reduced_decode():
    half = replace(PAPER_CONTRACT, crop_top=64, crop_bottom=136, decode_reduce=2)
    assert jpeg_reduction(replace(half, decode_reduce=0)) == 1  # 72 rows: the rule keeps the full decode
    assert jpeg_reduction(half) == 2
    assert PreprocessContract.from_json(half.to_json()) == half
    assert "decode_reduce" not in PAPER_CONTRACT.to_json()  # contracts without it read as they always did
    for bad in (3, -2, 2.0, "2", None):
        with pytest.raises(ContractError, match="decode_reduce"):
            replace(half, decode_reduce=bad)
    with pytest.raises(ContractError, match="grid"):
        replace(half, crop_top=65)
    # the served pixels: the 36 decoded rows resized to the network's 64, as training sees them
    rgb = np.random.default_rng(0).integers(0, 255, (80, 160, 3), dtype=np.uint8)
    assert frame_to_network_image(rgb, half).shape == (64, 64, 3)


def test_jpeg_reduction():
    assert jpeg_reduction(PAPER_CONTRACT) == 2  # 160x80 decode still >= 64x64
    assert jpeg_reduction(NVIDIA_CONTRACT) == 1  # 200 wide needs the full 320
    assert jpeg_reduction(replace(PAPER_CONTRACT, width=32, height=32)) == 4
    assert jpeg_reduction(replace(PAPER_CONTRACT, crop_top=61)) == 1  # crop not on the reduced grid


def test_reduced_decode_feeds_nearly_the_same_input():
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(FRAME, cv2.COLOR_RGB2BGR))
    half = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_REDUCED_COLOR_2), cv2.COLOR_BGR2RGB)
    full = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    a, b = preprocess(half, PAPER_CONTRACT), preprocess(full, PAPER_CONTRACT)
    assert a.shape == b.shape and np.abs(a - b).mean() < 4 / 255  # ~1 % of the range
