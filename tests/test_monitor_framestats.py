"""#53: the frame-statistics monitor (the frame's brightness and contrast against nominal frames') and its
combination with another score: the graphs answer what numpy computes, a washed-out frame scores far above nominal
ones, the combined score is the larger part in units of its own alarm threshold, and ``rbc monitor fit
--with-framestats`` writes a file drive_server scores that way, its steering untouched."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_server import SAMPLE_LOG
from test_monitor_ensemble import FRAMES, GENERALIST, _calibration_set, _outputs

from drive_server.serving.contract import PreprocessContract
from drive_server.serving.model import SteeringModel
from drive_server.serving.monitor import FRAME, STEERING, MonitorGraph
from models.monitoring.framestats import (
    combine_scores,
    fit_framestats,
    framestats_graph,
    framestats_scores,
)
from protocol.errors import BadValue

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")


def _nominal(contract: PreprocessContract, n: int = 200, seed: int = 0) -> np.ndarray:
    """Frames of varied brightness and contrast around a mid-grey road, in the contract's layout."""
    rng = np.random.default_rng(seed)
    shape = contract.input_shape[1:]
    base = rng.random((n, *shape), dtype=np.float32) - 0.5
    return (base * rng.uniform(0.3, 0.6, (n, 1, 1, 1)) + rng.uniform(-0.1, 0.1, (n, 1, 1, 1))).astype(np.float32)


def _run(graph: bytes, *feeds: np.ndarray) -> np.ndarray:
    session = ort.InferenceSession(graph, providers=["CPUExecutionProvider"])
    names = [i.name for i in session.get_inputs()]
    return np.asarray(session.run(None, dict(zip(names, feeds, strict=True)))[0]).reshape(-1)


@pytest.mark.parametrize("layout", ["nhwc", "nchw"])
@pytest.mark.parametrize("opset", [17, 18])
def test_the_graph_is_the_mahalanobis_distance_and_a_washed_out_frame_stands_out(layout, opset):
    contract = PreprocessContract(layout=layout)
    frames = _nominal(contract)
    mu, whiten = fit_framestats(frames, contract)
    graph = framestats_graph(contract, mu, whiten, opset=opset)
    test = _nominal(contract, 20, seed=1)
    washed = np.clip(test * 0.2 + 0.45, -0.5, 0.5)  # light many times the default: bright and flat
    assert np.allclose(_run(graph, test), framestats_scores(test, contract, mu, whiten), atol=1e-3)
    nominal, bright = framestats_scores(test, contract, mu, whiten), _run(graph, washed)
    assert bright.min() > 2 * nominal.max()


def test_too_few_nominal_frames_is_one_line():
    contract = PreprocessContract()
    with pytest.raises(BadValue, match="at least 30 nominal frames"):
        fit_framestats(_nominal(contract, 10), contract)


def _steering_graph() -> bytes:
    """A two-input score: |served steering| + 0 * the frame's mean (the ensemble's inputs, scripted)."""
    from onnx import TensorProto, helper

    nodes = [helper.make_node("ReduceMean", ["image"], ["m"], axes=[1, 2, 3], keepdims=0),
             helper.make_node("Mul", ["m", "zero"], ["m0"]),
             helper.make_node("Reshape", ["served_steering", "flat"], ["s"]),
             helper.make_node("Abs", ["s"], ["a"]),
             helper.make_node("Add", ["a", "m0"], ["score"])]
    inits = [helper.make_tensor("zero", TensorProto.FLOAT, [], [0.0]),
             helper.make_tensor("flat", TensorProto.INT64, [1], [-1])]
    graph = helper.make_graph(nodes, "scripted", [
        helper.make_tensor_value_info("image", TensorProto.FLOAT, ["batch", 64, 64, 3]),
        helper.make_tensor_value_info("served_steering", TensorProto.FLOAT, ["batch", 1])],
        [helper.make_tensor_value_info("score", TensorProto.FLOAT, ["batch"])], inits)
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8).SerializeToString()


def test_the_combined_score_is_the_larger_part_in_units_of_its_own_alarm():
    contract = PreprocessContract()
    mu, whiten = fit_framestats(_nominal(contract), contract)
    second = framestats_graph(contract, mu, whiten)
    combined = combine_scores(_steering_graph(), second, (0.2, 3.0))
    frames = np.concatenate([_nominal(contract, 4, seed=2), np.full((2, 64, 64, 3), 0.45, np.float32)])
    steering = np.array([[0.0], [0.5], [-0.1], [0.05], [0.0], [0.5]], np.float32)
    want = np.maximum(np.abs(steering[:, 0]) / 0.2, framestats_scores(frames, contract, mu, whiten) / 3.0)
    assert np.allclose(_run(combined, frames, steering), want, rtol=1e-4, atol=1e-4)
    graph = MonitorGraph(combined, "t", (FRAME, STEERING))  # as drive_server loads it: frame, then steering
    assert graph.score(frames[1:2], 0.5) == pytest.approx(float(want[1]), rel=1e-4)
    with pytest.raises(BadValue, match="must be > 0"):
        combine_scores(_steering_graph(), second, (0.0, 3.0))
    with pytest.raises(BadValue, match="frame only"):
        combine_scores(second, _steering_graph(), (1.0, 1.0))


@pytest.fixture(scope="module")
def members(tmp_path_factory):
    from tools.monitoreval.modelfiles import degraded_model

    folder = tmp_path_factory.mktemp("fs-members")
    return [degraded_model(GENERALIST, folder, 0.1, seed) for seed in (1, 2)]


def test_fit_with_framestats_writes_a_file_the_server_scores_as_the_larger_part(members, tmp_path, capsys):
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
    from drive_server.serving.pipeline import DriveConfig, DrivePipeline
    from drive_server.serving.preprocess import preprocess
    from models.monitoring.frames import load_runs
    from protocol import decode_image, parse_telemetry
    from tools.cli import main

    calibration = _calibration_set(tmp_path / "calibration")
    out = tmp_path / "both.onnx"
    args = ["monitor", "fit", str(GENERALIST), "--score", "ensemble", "--member", str(members[0]), "--member",
            str(members[1]), "--with-framestats", "--data", str(SAMPLE_LOG), "--stride", "1", "--calibration",
            str(calibration), "--out", str(out)]
    assert main(args) == 0
    assert "monitor ensemble+framestats, warning at" in capsys.readouterr().out
    spec, graph = SteeringModel(out).monitor()
    assert spec.inputs == (FRAME, STEERING) and graph.wants_steering
    first, second = spec.calibration["parts"]
    assert (first["score"], second["score"]) == ("ensemble", "framestats") and min(first["alarm"], second["alarm"]) > 0
    assert spec.calibration["framestats_frames"] == 36 and spec.calibration["members"][0]["file"] == members[0].name

    model = SteeringModel(out)
    nominal = np.concatenate(load_runs([SAMPLE_LOG], model.contract, 1))
    mu, whiten = fit_framestats(nominal, model.contract)
    pipeline = DrivePipeline(model, DriveConfig(monitor=MonitorPolicy(MonitorMode.WARN, budget_ms=None)))
    reference = DrivePipeline(SteeringModel(GENERALIST))
    monitor = pipeline.client_monitor("t")
    for frame in FRAMES[:3]:
        command, _ = pipeline.run(parse_telemetry(frame.payload()), pipeline.smoother(), monitor)
        assert command == reference.run(parse_telemetry(frame.payload()), reference.smoother())[0]
        x = preprocess(decode_image(frame.payload()["image"], reduce=pipeline.reduce), model.contract)
        outs = np.array([_outputs(m, x)[0] for m in members])
        ensemble = abs(model.predict(x) - outs.mean()) + outs.std()
        stats = float(framestats_scores(x, model.contract, mu, whiten)[0])
        assert monitor.last is not None
        assert monitor.last.score == pytest.approx(max(ensemble / first["alarm"], stats / second["alarm"]), rel=1e-3)


@pytest.mark.parametrize(("extra", "problem"), [
    (["--score", "predictor", "--with-framestats", "--data", str(SAMPLE_LOG)], "--with-framestats goes beside"),
    (["--score", "shift", "--with-framestats"], "--with-framestats goes beside"),
    (["--score", "framestats"], "training data (--data)"),
])
def test_a_framestats_fit_without_what_it_needs_is_one_line(extra, problem, tmp_path, capsys):
    from tools.cli import main

    calibration = _calibration_set(tmp_path / "calibration", runs=1)
    assert main(["monitor", "fit", str(GENERALIST), "--calibration", str(calibration), "--out",
                 str(tmp_path / "o.onnx"), *extra]) == 2
    err = capsys.readouterr().err
    assert problem in err and "Traceback" not in err and not (tmp_path / "o.onnx").exists()


def test_keep_with_framestats_puts_the_camera_check_beside_the_monitor_a_file_carries(tmp_path, capsys):
    """How the bundled files got theirs: the carried monitor (here MC-dropout of the generalist's network) calibrated
    afresh beside the frame statistics; its own record survives, and a file that has the camera check (the bundled
    generalist too) refuses a second."""
    from tools.cli import main

    calibration = _calibration_set(tmp_path / "calibration")
    carried, out = tmp_path / "mcd.onnx", tmp_path / "kept.onnx"
    assert main(["monitor", "fit", str(GENERALIST), "--score", "mcdropout", "--calibration", str(calibration),
                 "--out", str(carried)]) == 0
    base = ["monitor", "fit", "--score", "keep", "--with-framestats", "--data", str(SAMPLE_LOG), "--stride", "1",
            "--calibration", str(calibration), "--out"]
    assert main([*base[:2], str(carried), *base[2:], str(out)]) == 0
    spec, graph = SteeringModel(out).monitor()
    old, _ = SteeringModel(carried).monitor()
    assert spec.score == "mcdropout+framestats" and spec.inputs == old.inputs and graph.wants_steering
    assert spec.calibration["samples"] == old.calibration["samples"] and spec.calibration["recalibrated"]
    assert spec.calibration["framestats_train"] == [SAMPLE_LOG.name]
    for twice in (out, GENERALIST):
        capsys.readouterr()
        assert main([*base[:2], str(twice), *base[2:], str(tmp_path / "twice.onnx")]) == 2
        err = capsys.readouterr().err
        assert "has the frame statistics already" in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "twice.onnx").exists()


def test_calibration_frames_are_read_one_run_at_a_time_and_a_bad_folder_is_refused_first(tmp_path):
    """An hour of PilotNet's 66x200 input is 9 GB: the runs come one at a time, the folders checked before any."""
    from models.monitoring.frames import iter_runs, load_runs

    contract = SteeringModel(GENERALIST).contract
    runs = iter_runs([SAMPLE_LOG], contract)
    first = next(runs)
    assert np.array_equal(first, load_runs([SAMPLE_LOG], contract)[0])
    (tmp_path / "empty").mkdir()
    with pytest.raises(BadValue):
        iter_runs([SAMPLE_LOG, tmp_path / "empty"], contract)  # raises at the call, before a frame is read
