"""``rbc import-peer``: a Keras 1 PilotNet .h5 (the layout of naokishibuya/car-behavioral-cloning's model.h5)
becomes an ONNX model the drive server serves, with the same output as the Keras network.

The .h5 files here are synthetic (the peer's layer names, shapes and attributes, random weights); the
reference forward pass is written independently, in NumPy and in Keras' NHWC order.
"""

from __future__ import annotations

import json
import marshal
from pathlib import Path

import numpy as np
import pytest

h5py = pytest.importorskip("h5py", reason="rbc import-peer reads .h5 files with h5py (pip install -e '.[peer]')")
pytest.importorskip("torch", reason="rbc import-peer needs the train extra (torch, onnx)")
pytest.importorskip("onnx", reason="rbc import-peer needs the train extra (torch, onnx)")

import cv2  # noqa: E402
import onnxruntime as ort  # noqa: E402

from drive_server.serving.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY, PreprocessContract  # noqa: E402
from drive_server.serving.model import SteeringModel  # noqa: E402
from drive_server.serving.pipeline import DrivePipeline  # noqa: E402
from protocol.datalog import read_log  # noqa: E402
from protocol.jpeg import read_jpeg_file  # noqa: E402
from tools.cli import main  # noqa: E402

SAMPLE = Path(__file__).resolve().parent / "data" / "udacity-sample"
CONVS = [(24, 5, 2), (36, 5, 2), (48, 5, 2), (64, 3, 1), (64, 3, 1)]  # filters, kernel, stride
DENSE = [100, 50, 10, 1]


def _layer(kind: str, name: str, **cfg) -> dict:
    return {"class_name": kind, "config": {"name": name, "trainable": True, **cfg}}


def write_keras1_h5(path, seed=0, lambda_code=lambda x: x / 127.5 - 1.0, dense_units=DENSE, drop=None,
                    dim_ordering="tf"):
    """A Keras 1.2 Sequential .h5 laid out like the peer's model.h5; returns {layer: (W, b)} (Keras layouts)."""
    rng = np.random.default_rng(seed)
    function = [marshal.dumps(lambda_code.__code__).decode("latin-1"), None, None]
    layers = [_layer("Lambda", "lambda_1", function=function, function_type="lambda", arguments={},
                     output_shape=None, output_shape_type="raw", input_dtype="float32",
                     batch_input_shape=[None, 66, 200, 3])]
    weights, channels = {}, 3
    for i, (filters, k, s) in enumerate(CONVS, 1):
        name = f"convolution2d_{i}"
        layers.append(_layer("Convolution2D", name, nb_filter=filters, nb_row=k, nb_col=k, subsample=[s, s],
                             activation="elu", border_mode="valid", dim_ordering=dim_ordering, bias=True,
                             init="glorot_uniform"))
        fan_in = channels * k * k
        weights[name] = (rng.normal(0, (1.5 / fan_in) ** 0.5, (k, k, channels, filters)).astype(np.float32),
                         rng.normal(0, 0.05, filters).astype(np.float32))
        channels = filters
    layers += [_layer("Dropout", "dropout_1", p=0.5), _layer("Flatten", "flatten_1")]
    features = 64 * 1 * 18
    for i, units in enumerate(dense_units, 1):
        name = f"dense_{i}"
        layers.append(_layer("Dense", name, input_dim=features, output_dim=units, bias=True, init="glorot_uniform",
                             activation="elu" if i < len(dense_units) else "linear"))
        weights[name] = (rng.normal(0, (1.5 / features) ** 0.5, (features, units)).astype(np.float32),
                         rng.normal(0, 0.05, units).astype(np.float32))
        features = units
    with h5py.File(path, "w") as f:
        f.attrs["keras_version"] = "1.2.1"
        f.attrs["model_config"] = json.dumps({"class_name": "Sequential", "config": layers})
        f.attrs["training_config"] = json.dumps({"loss": "mean_squared_error"})
        group = f.create_group("model_weights")
        names = [layer["config"]["name"] for layer in layers]
        group.attrs["layer_names"] = np.array([n.encode() for n in names])
        for name in names:
            g = group.create_group(name)
            if name not in weights or name == drop:
                g.attrs["weight_names"] = np.array([], dtype=np.float64)
                continue
            w_name, b_name = f"{name}_W:0", f"{name}_b:0"
            g.attrs["weight_names"] = np.array([w_name.encode(), b_name.encode()])
            g.create_dataset(w_name, data=weights[name][0])
            g.create_dataset(b_name, data=weights[name][1])
    return weights


def keras_forward_nhwc(weights: dict, yuv: np.ndarray, flatten: str = "nhwc") -> float:
    """The Keras model on one YUV uint8 image (66, 200, 3), in float64, NHWC throughout like TensorFlow."""
    x = yuv.astype(np.float64) / 127.5 - 1.0
    elu = lambda z: np.where(z > 0, z, np.expm1(np.minimum(z, 0)))  # noqa: E731
    for i, (_, k, s) in enumerate(CONVS, 1):
        w, b = weights[f"convolution2d_{i}"]
        rows, cols = (x.shape[0] - k) // s + 1, (x.shape[1] - k) // s + 1
        windows = np.lib.stride_tricks.sliding_window_view(x, (k, k), axis=(0, 1))[::s, ::s][:rows, :cols]
        x = elu(np.einsum("hwcij,ijco->hwo", windows, w.astype(np.float64)) + b)
    x = x.reshape(-1) if flatten == "nhwc" else x.transpose(2, 0, 1).reshape(-1)  # "nchw": the naive mistake
    for i in range(1, len(DENSE) + 1):
        w, b = weights[f"dense_{i}"]
        x = x @ w.astype(np.float64) + b
        x = elu(x) if i < len(DENSE) else x
    return float(x[0])


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("peer")
    weights = write_keras1_h5(tmp / "model.h5")
    assert main(["import-peer", "--h5", str(tmp / "model.h5"), "--out", str(tmp / "peer.onnx")]) == 0
    return weights, tmp / "peer.onnx"


def _network_images(count: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (count, 66, 200, 3), dtype=np.uint8)


def test_onnx_output_equals_the_keras_forward_pass_in_nhwc_order(imported):
    weights, onnx_path = imported
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    for rgb in _network_images(4):
        got = float(session.run(None, {"image": rgb[None].astype(np.float32)})[0].reshape(-1)[0])
        yuv = cv2.cvtColor(rgb, cv2.COLOR_BGR2YUV)  # OpenCV 3.1's RGB2YUV, the default --yuv opencv31
        want = keras_forward_nhwc(weights, yuv)
        assert got == pytest.approx(want, abs=1e-4)
        # the check can tell: flattening NCHW without permuting the first dense layer's rows gives another output
        assert abs(keras_forward_nhwc(weights, yuv, flatten="nchw") - want) > 1e-2


def test_drive_server_serves_it_with_the_peers_preprocessing(imported):
    """Real frames through drive_server's pipeline = the peer's utils.preprocess (cv2) + the Keras network."""
    weights, onnx_path = imported
    model = SteeringModel(onnx_path)
    model.warm_up()
    assert model.contract == PreprocessContract(width=200, height=66, crop_top=60, crop_bottom=135, color="rgb",
                                                scale=1.0, offset=0.0, layout="nhwc", interpolation="linear")
    pipeline = DrivePipeline(model)
    samples, _ = read_log(SAMPLE)
    for s in samples[:3]:
        rgb = read_jpeg_file(s.center)
        yuv = cv2.cvtColor(cv2.resize(rgb[60:-25], (200, 66)), cv2.COLOR_BGR2YUV)
        assert pipeline.steer(read_jpeg_file(s.center, reduce=pipeline.reduce)) == pytest.approx(
            keras_forward_nhwc(weights, yuv), abs=1e-4)


def test_metadata_names_the_source_and_the_yuv_mode(imported):
    _, onnx_path = imported
    meta = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"]).get_modelmeta()
    info = json.loads(meta.custom_metadata_map[METADATA_MODEL_INFO_KEY])
    assert info["repository"] == "naokishibuya/car-behavioral-cloning" and info["yuv"] == "opencv31"
    assert info["commit"].startswith("unknown")  # a synthetic file is not the commit's model.h5
    assert info["parameters"] == 252219 and info["keras_version"] == "1.2.1"
    assert json.loads(meta.custom_metadata_map[METADATA_KEY])["color"] == "rgb"


def test_the_real_files_hash_is_credited_to_its_commit(tmp_path, monkeypatch):
    from models.onnxfiles import peer_keras

    write_keras1_h5(tmp_path / "model.h5")
    weights = peer_keras.read_peer_h5(tmp_path / "model.h5")
    monkeypatch.setattr(peer_keras, "PEER_H5_SHA256", weights.sha256)
    assert peer_keras.model_info(weights, tmp_path / "model.h5", "correct")["commit"] == "edf2061"


@pytest.mark.parametrize(("mode", "code"), [("opencv31", cv2.COLOR_BGR2YUV), ("correct", cv2.COLOR_RGB2YUV)])
def test_the_yuv_modes_are_opencvs_conversions(mode, code):
    import torch

    from models.onnxfiles.peer_keras import OpenCVYuv, yuv_matrix

    images = _network_images(3, seed=7)
    m, offset = yuv_matrix(mode)
    graph = OpenCVYuv(mode)
    for rgb in images:
        want = cv2.cvtColor(rgb, code).astype(np.float64)
        linear = np.clip(rgb.astype(np.float64) @ m.T + offset, 0, 255)
        assert np.abs(linear - want).max() <= 1.0  # the matrix: within one unit (uint8 rounding)
        got = graph(torch.from_numpy(rgb.astype(np.float32)).permute(2, 0, 1)[None])[0].permute(1, 2, 0).numpy()
        assert np.array_equal(got, want)  # the graph: OpenCV's fixed-point rounding, bit for bit


def _expect_one_line_error(capsys, tmp_path, h5) -> str:
    out = tmp_path / "out.onnx"
    assert main(["import-peer", "--h5", str(h5), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("rbc import-peer: error: ") and "Traceback" not in err
    assert not out.exists()
    return err


def test_a_missing_file_is_one_line(capsys, tmp_path):
    assert "no such file" in _expect_one_line_error(capsys, tmp_path, tmp_path / "nope.h5")


def test_a_corrupt_file_is_one_line(capsys, tmp_path):
    (tmp_path / "model.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(256)) * 4)
    assert "not an HDF5 file" in _expect_one_line_error(capsys, tmp_path, tmp_path / "model.h5")


@pytest.mark.parametrize(("change", "says"), [
    ({"dense_units": [64, 50, 10, 1]}, "layer 9 (dense_1)"),
    ({"drop": "convolution2d_3"}, "convolution2d_3"),
    ({"dim_ordering": "th"}, "dim_ordering 'th'"),
    ({"lambda_code": lambda x: x / 255.0 - 0.5}, "x/127.5 - 1"),
])
def test_a_file_with_other_layers_is_one_line(capsys, tmp_path, change, says):
    write_keras1_h5(tmp_path / "model.h5", **change)
    assert says in _expect_one_line_error(capsys, tmp_path, tmp_path / "model.h5")


def test_an_hdf5_file_that_is_no_keras_model_is_one_line(capsys, tmp_path):
    with h5py.File(tmp_path / "model.h5", "w") as f:
        f.create_dataset("x", data=np.zeros(3))
    assert "not a Keras model file" in _expect_one_line_error(capsys, tmp_path, tmp_path / "model.h5")
