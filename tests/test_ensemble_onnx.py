"""``rbc ensemble`` / ``models.onnxfiles.ensemble_onnx``: several ONNX models averaged into one file, checked against
its members, their contract kept, mismatched members and bad files refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers_server import build_shallow

from drive_server.serving.contract import METADATA_MODEL_INFO_KEY
from drive_server.serving.model import SteeringModel
from tools.cli import main as rbc

ort = pytest.importorskip("onnxruntime")
pytest.importorskip("onnx", reason="an ensemble is built as one ONNX graph")


def _run(path: Path, x: np.ndarray) -> np.ndarray:
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    return np.concatenate([session.run(None, {session.get_inputs()[0].name: x[i:i + 1]})[0].ravel()
                           for i in range(len(x))])


def test_the_ensemble_answers_the_mean_of_its_members_and_keeps_their_contract(tmp_path: Path) -> None:
    members = [build_shallow(tmp_path / f"m{k}.onnx", seed=k) for k in range(3)]
    out = tmp_path / "ens.onnx"
    assert rbc(["ensemble", *map(str, members), "--out", str(out), "--serve-smooth", "0.5"]) == 0
    shape = SteeringModel(members[0]).contract.input_shape[1:]
    x = np.random.default_rng(1).random((5, *shape), dtype=np.float32) - 0.5
    answers = np.stack([_run(m, x) for m in members])
    assert np.ptp(answers, axis=0).min() > 1e-3  # the members disagree: the mean means something
    assert np.allclose(_run(out, x), answers.mean(axis=0), atol=1e-6)
    served = SteeringModel(out)
    assert served.contract == SteeringModel(members[0]).contract and served.smoothing == 0.5
    meta = ort.InferenceSession(str(out)).get_modelmeta().custom_metadata_map
    info = json.loads(meta[METADATA_MODEL_INFO_KEY])
    assert [m["file"] for m in info["ensemble"]] == ["m0.onnx", "m1.onnx", "m2.onnx"] and info["smoothing"] == 0.5


def test_the_members_smoothing_is_kept_when_they_agree_and_must_be_chosen_when_they_do_not(tmp_path: Path) -> None:
    plain = [build_shallow(tmp_path / f"p{k}.onnx", seed=k) for k in range(2)]
    smoothed = tmp_path / "s.onnx"
    assert rbc(["mirror", str(plain[1]), "--out", str(smoothed), "--serve-smooth", "0.5"]) == 0
    assert rbc(["ensemble", *map(str, plain), "--out", str(tmp_path / "a.onnx")]) == 0
    assert SteeringModel(tmp_path / "a.onnx").smoothing == 1.0
    assert rbc(["ensemble", str(plain[0]), str(smoothed), "--out", str(tmp_path / "b.onnx")]) == 2
    assert rbc(["ensemble", str(plain[0]), str(smoothed), "--out", str(tmp_path / "b.onnx"),
                "--serve-smooth", "1"]) == 0
    assert SteeringModel(tmp_path / "b.onnx").smoothing == 1.0


def test_bad_members_and_paths_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a, b = (build_shallow(tmp_path / f"{n}.onnx", seed=i) for i, n in enumerate("ab"))
    nchw = build_shallow(tmp_path / "nchw.onnx", seed=3, layout="nchw")
    smoothed = tmp_path / "s.onnx"
    assert rbc(["mirror", str(b), "--out", str(smoothed), "--serve-smooth", "0.5"]) == 0
    not_onnx = tmp_path / "x.onnx"
    not_onnx.write_bytes(b"not a model")
    cases = [([str(a), "--out", str(tmp_path / "one.onnx")], "at least two models"),
             ([str(a), str(nchw), "--out", str(tmp_path / "mixed.onnx")], "preprocessing differs"),
             ([str(a), str(not_onnx), "--out", str(tmp_path / "y.onnx")], "not an ONNX model"),
             ([str(a), str(tmp_path / "missing.onnx"), "--out", str(tmp_path / "z.onnx")], "no model at"),
             ([str(a), str(b), "--out", str(a)], "must not be one of the models"),
             ([str(a), str(smoothed), "--out", str(tmp_path / "w.onnx")], "--serve-smooth"),
             ([str(a), str(b), "--out", str(tmp_path / "v.txt")], "ending in .onnx")]
    capsys.readouterr()
    for argv, says in cases:
        assert rbc(["ensemble", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("rbc ensemble: error") and says in err and "\n" not in err, err
    assert not [p.name for p in tmp_path.iterdir() if p.stem in {"one", "mixed", "y", "z", "w", "v"}]
