"""#53: MC-dropout as the served network under fixed dropout masks: each sample is the network with one mask per
hidden dense layer baked into the next layer's weights (nothing else changed), drawn from the seed; a network
trained without dropout is refused in one line; ``rbc monitor fit --score mcdropout`` writes a file the server
scores as the ensemble score over those samples."""

from __future__ import annotations

import numpy as np
import pytest
from test_monitor_ensemble import FRAMES, GENERALIST, PRETRAINED, _calibration_set, _outputs

from drive_server.serving.model import SteeringModel
from drive_server.serving.monitor import FRAME, STEERING
from models.monitoring.mcdropout import dropout_members, dropout_rate
from protocol.errors import BadValue

onnx = pytest.importorskip("onnx")


def _weights(path):
    from onnx import numpy_helper

    return {i.name: numpy_helper.to_array(i) for i in onnx.load(str(path)).graph.initializer}


def test_each_sample_is_the_network_with_a_dropout_mask_on_the_next_layers_inputs(tmp_path):
    rate = dropout_rate(GENERALIST)
    members = dropout_members(GENERALIST, tmp_path / "a", samples=3, seed=5)
    served = _weights(GENERALIST)
    masked = {"net.head.4.weight", "net.head.7.weight", "net.head.10.weight"}  # the layers after the 3 hidden ReLUs
    seen = []
    for path in members:
        w = _weights(path)
        assert set(w) == set(served)
        for name in served:
            if name not in masked:
                assert np.array_equal(w[name], served[name]), name
                continue
            ratio = np.divide(w[name], served[name], out=np.ones_like(w[name]), where=served[name] != 0)
            column = ratio[0]  # one factor per input unit (column), the same in every row
            assert np.allclose(ratio, column[None, :], atol=1e-5)
            kept = column[column != 0]
            assert np.allclose(kept, 1 / (1 - rate), rtol=1e-5) and 0 < len(kept) <= len(column)
            if len(column) == 64:  # a quarter of 64 units dropped: never none (the seed is fixed)
                assert 0.5 < len(kept) / len(column) < 0.95
        seen.append(w["net.head.4.weight"])
        assert "rbc.monitor" not in {p.key for p in onnx.load(str(path)).metadata_props}
    assert not np.array_equal(seen[0], seen[1])
    again = dropout_members(GENERALIST, tmp_path / "b", samples=3, seed=5)
    assert [p.read_bytes() for p in again] == [p.read_bytes() for p in members]  # the seed fixes the masks


def test_a_network_trained_without_dropout_is_refused_in_one_line(tmp_path):
    with pytest.raises(BadValue, match="trained without dropout") as info:
        dropout_members(PRETRAINED / "generalist_pilotnet.onnx", tmp_path)
    assert "\n" not in str(info.value)


def test_fit_mcdropout_writes_a_file_the_server_scores_over_the_masked_samples(tmp_path, capsys):
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
    from drive_server.serving.pipeline import DriveConfig, DrivePipeline
    from drive_server.serving.preprocess import preprocess
    from protocol import decode_image, parse_telemetry
    from tools.cli import main

    out = tmp_path / "mcd.onnx"
    assert main(["monitor", "fit", str(GENERALIST), "--score", "mcdropout", "--samples", "3", "--calibration",
                 str(_calibration_set(tmp_path / "calibration")), "--out", str(out)]) == 0
    assert "monitor mcdropout, warning at" in capsys.readouterr().out
    spec, graph = SteeringModel(out).monitor()
    assert spec.inputs == (FRAME, STEERING) and graph.wants_steering
    assert (spec.calibration["samples"], spec.calibration["dropout"]) == (3, dropout_rate(GENERALIST))
    samples = dropout_members(GENERALIST, tmp_path / "samples", samples=3, seed=0)
    model = SteeringModel(out)
    pipeline = DrivePipeline(model, DriveConfig(monitor=MonitorPolicy(MonitorMode.WARN, budget_ms=None)))
    monitor = pipeline.client_monitor("t")
    for frame in FRAMES[:3]:
        pipeline.run(parse_telemetry(frame.payload()), pipeline.smoother(), monitor)
        x = preprocess(decode_image(frame.payload()["image"], reduce=pipeline.reduce), model.contract)
        outs = np.array([_outputs(m, x)[0] for m in samples])
        assert monitor.last is not None
        assert monitor.last.score == pytest.approx(abs(model.predict(x) - outs.mean()) + outs.std(), rel=1e-3)
