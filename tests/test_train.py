"""End to end on real frames: train a few steps, export, load the ONNX model as the drive server does."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
ort = pytest.importorskip("onnxruntime")

from drive_server.serving.contract import (  # noqa: E402
    METADATA_KEY,
    METADATA_MODEL_INFO_KEY,
    NVIDIA_CONTRACT,
    PAPER_CONTRACT,
    PreprocessContract,
)
from drive_server.serving.preprocess import preprocess, to_input_tensor  # noqa: E402
from models.data.framecache import build_cache, load_frame  # noqa: E402
from models.networks.checkpoint import exported_weights  # noqa: E402
from models.networks.nets import ContractInput, build_model  # noqa: E402
from models.networks.runfiles import RunRecord  # noqa: E402
from models.training import train as train_mod  # noqa: E402
from models.training.train import RunDirError, TrainConfig, steps_per_epoch, train  # noqa: E402
from protocol.datalog import read_log  # noqa: E402

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
pytestmark = pytest.mark.slow


def _config(out: Path, **kw) -> TrainConfig:
    base = dict(data=[str(SAMPLE)], out=str(out), epochs=1, max_steps_per_epoch=3, threads=1, decode_workers=1,
                progress=False, seed=11)
    return TrainConfig(**{**base, **kw})


def test_paper_step_counts() -> None:
    assert steps_per_epoch(9680, 256, 64) == 2432
    assert train_mod.validation_steps(2421, 256) == 10


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("run") / "shallow"
    return train(_config(out, epochs=2))


def test_run_directory_contents(run) -> None:
    d = run.run_dir
    assert sorted(p.name for p in d.iterdir()) == ["checkpoint.pt", "config.json", "history.csv", "loss.png",
                                                   "model.onnx"]
    record = json.loads((d / "config.json").read_text())
    assert record["config"]["seed"] == 11 and record["config"]["batch_size"] == 256
    assert record["config"]["learning_rate"] == 1e-3 and record["config"]["aug_loops"] == 64
    assert record["resolved"]["deletion_rate"] == 0.7 and record["resolved"]["train_samples"] == 28
    # the default split holds out contiguous blocks: 7 of 36 frames, 1 training frame dropped beside them
    assert record["resolved"]["val_samples"] == 7 and record["resolved"]["steps_per_epoch"] == 3
    assert record["config"]["split"] == "blocks" and record["resolved"]["split"]["kind"] == "blocks"
    assert record["config"]["export"] == "best" and record["result"]["export"] == "best"
    assert record["rows"] == {"rows": 36, "stride": 1, "skipped": 0, "unreadable": 0, "slow": 0, "turnround": 0,
                              "kept": 36, "train": 28, "val": 7, "gap": 1, "recordings": 1, "val_recordings": 1}
    assert record["logs"] == [{"path": str((SAMPLE / "driving_log.csv").resolve()), "rows": 36, "samples": 36,
                               "skipped": 0}]
    assert record["augment"]["perspective"] == 0.5 and record["contract"]["width"] == 64
    assert record["code_version"]
    rows = list(csv.DictReader((d / "history.csv").open()))
    assert [r["epoch"] for r in rows] == ["1", "2"] and set(rows[0]) == {"epoch", "train_loss", "val_loss", "seconds"}
    best = min(range(2), key=lambda i: float(rows[i]["val_loss"]))
    assert run.val_loss == pytest.approx(float(rows[best]["val_loss"]))
    assert record["result"]["exported_epoch"] == best + 1
    assert not list(d.glob(".*.tmp"))


def test_the_run_record_reads_what_training_wrote(run) -> None:
    """Issue 51: training, DAgger, drive-log, the model card and inspect read a run through one RunRecord."""
    record = RunRecord.load(run.run_dir)
    stored = json.loads((run.run_dir / "config.json").read_text())
    assert record.config == stored["config"] and record.resolved == stored["resolved"]
    assert record.result == stored["result"] and record.rows == stored["rows"] and record.logs == stored["logs"]
    assert record.recipe == stored["recipe"] and record.contract == stored["contract"]
    assert [h.as_dict() for h in record.history] == run.history  # typed rows, the values training kept
    assert all(isinstance(h.epoch, int) for h in record.history) and record.last_epoch.epoch == 2
    assert record.model_path == run.onnx and record.checkpoint_path.is_file() and record.finished
    assert TrainConfig.from_dict(record.config) == TrainConfig.from_dict(stored["config"])


def test_onnx_export_carries_the_contract_and_matches_pytorch(run) -> None:
    session = ort.InferenceSession(str(run.onnx), providers=["CPUExecutionProvider"])
    meta = session.get_modelmeta().custom_metadata_map
    assert PreprocessContract.from_json(meta[METADATA_KEY]) == PAPER_CONTRACT
    info = json.loads(meta[METADATA_MODEL_INFO_KEY])
    assert (info["arch"], info["behavior"], info["approach"]) == ("shallow", "simplistic", "ours")
    assert info["val_mse"] == pytest.approx(run.val_loss) and info["parameters"] == 14065
    inp = session.get_inputs()[0]
    assert inp.type == "tensor(float)" and list(inp.shape[1:]) == [64, 64, 3] and not isinstance(inp.shape[0], int)
    # real frames through the shared preprocessing; PyTorch from the checkpoint
    samples, _ = read_log(SAMPLE)
    images = build_cache(samples, PAPER_CONTRACT, ("center",), workers=1).frames[0]
    x = to_input_tensor(images, PAPER_CONTRACT)
    net = build_model("shallow", 64, 64)
    net.load_state_dict(exported_weights(run.run_dir / "checkpoint.pt"))
    with torch.no_grad():
        expected = ContractInput(net, "nhwc").eval()(torch.from_numpy(x)).numpy()
    got = session.run(None, {inp.name: x})[0]
    assert got.shape == (36, 1)
    assert np.abs(got - expected).max() < 1e-4
    assert run.export_diff < 1e-4


def test_drive_server_loads_the_exported_model(run) -> None:
    model_mod = pytest.importorskip("drive_server.serving.model")
    pipeline_mod = pytest.importorskip("drive_server.serving.pipeline")
    if not hasattr(model_mod, "SteeringModel") or not hasattr(pipeline_mod, "DrivePipeline"):
        pytest.skip("drive server pipeline API not available")
    model = model_mod.SteeringModel(run.onnx)
    assert model.contract == PAPER_CONTRACT
    pipeline = pipeline_mod.DrivePipeline(model)
    samples, _ = read_log(SAMPLE)
    session = ort.InferenceSession(str(run.onnx), providers=["CPUExecutionProvider"])
    for s in samples[:3]:
        rgb = load_frame(s.center, pipeline.reduce)
        direct = float(session.run(None, {session.get_inputs()[0].name: preprocess(rgb, PAPER_CONTRACT)})[0][0, 0])
        assert pipeline.steer(rgb) == pytest.approx(max(-1.0, min(1.0, direct)), abs=1e-6)


def test_existing_run_is_not_overwritten(run) -> None:
    with pytest.raises(RunDirError, match="--resume"):
        train(_config(run.run_dir))


class _StopAfter:
    """Stands in for Ctrl-C: asks the loop to stop after ``n`` training steps."""

    n = 2

    def __init__(self) -> None:
        self.checks = 0

    @property
    def requested(self) -> bool:
        self.checks += 1
        return self.checks > self.n

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        return None


def test_interrupt_then_resume_reproduces_an_uninterrupted_run(tmp_path: Path, monkeypatch) -> None:
    straight = train(_config(tmp_path / "a", epochs=2, max_steps_per_epoch=4))
    with monkeypatch.context() as m:
        m.setattr(train_mod, "_StopFlag", _StopAfter)
        stopped = train(_config(tmp_path / "b", epochs=2, max_steps_per_epoch=4))
    assert stopped.interrupted and stopped.onnx is None
    assert (tmp_path / "b" / "checkpoint.pt").exists() and not (tmp_path / "b" / "model.onnx").exists()
    resumed = train(TrainConfig(data=[], out=str(tmp_path / "b"), threads=1, progress=False), resume=True)
    assert not resumed.interrupted and resumed.onnx is not None
    losses = [v for h in straight.history for v in (h["train_loss"], h["val_loss"])]
    assert [v for h in resumed.history for v in (h["train_loss"], h["val_loss"])] == pytest.approx(losses, rel=1e-6)


def test_nothing_to_resume(tmp_path: Path) -> None:
    with pytest.raises(RunDirError, match="nothing to resume"):
        train(_config(tmp_path / "none"), resume=True)


def test_cli_pilotnet_nvidia_approach(tmp_path: Path) -> None:
    from tools.cli import main

    out = tmp_path / "pilotnet"
    rc = main(["train", "--recipe", "pilotnet_nvidia", "--data", str(SAMPLE), "--out", str(out),
               "--epochs", "1", "--max-steps-per-epoch", "1", "--threads", "1", "--no-progress"])
    assert rc == 0
    session = ort.InferenceSession(str(out / "model.onnx"), providers=["CPUExecutionProvider"])
    meta = session.get_modelmeta().custom_metadata_map
    assert PreprocessContract.from_json(meta[METADATA_KEY]) == NVIDIA_CONTRACT
    assert json.loads(meta[METADATA_MODEL_INFO_KEY])["parameters"] == 252219
    assert list(session.get_inputs()[0].shape[1:]) == [66, 200, 3]
    record = json.loads((out / "config.json").read_text())
    assert record["resolved"]["deletion_rate"] == 0.0
    # the bundled recipe's settings, the command line's --epochs over its 2, all kept as a recipe in the record
    assert record["recipe"]["augmentation"]["aug_loops"] == 8 and record["recipe"]["data"]["split"] == "random"
    assert record["recipe"]["training"]["epochs"] == 1 and record["config"]["epochs"] == 1


def test_row_stride_trains_as_a_log_of_every_nth_row(tmp_path: Path) -> None:
    """--row-stride 3 is the run on a log holding every third row (the PilotNet generalist's recipe)."""
    import shutil

    thinned = tmp_path / "thinned"
    shutil.copytree(SAMPLE, thinned)
    lines = (SAMPLE / "driving_log.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    (thinned / "driving_log.csv").write_text("".join(lines[::3]), encoding="utf-8")
    strided = train(_config(tmp_path / "strided", row_stride=3, export="last"))
    reference = train(_config(tmp_path / "reference", data=[str(thinned)], export="last"))
    assert "1 row in 3 used" in strided.info["summary"]
    assert strided.info["summary"].split(" used, ", 1)[1] == reference.info["summary"].split("images), ", 1)[1]
    a = exported_weights(strided.run_dir / "checkpoint.pt", "last")
    b = exported_weights(reference.run_dir / "checkpoint.pt", "last")
    assert all(torch.equal(a[k], b[k]) for k in a)
    with pytest.raises(ValueError, match="row_stride must be 1..1000"):
        _config(tmp_path / "bad", row_stride=0)


def test_rbc_train_piped_prints_each_line_once_in_plain_words(tmp_path: Path) -> None:
    """Issue 55: piped (``2>&1 | tail``), ``rbc train`` drew tqdm bars, printed every summary line twice (once more
    as ``INFO models.training.train:``, and the epochs only after the last one), in internal names
    (``simplistic/shallow-wide/ours: 117 training, 50 validation samples``), and wrote no loss.png though the
    guides said it did."""
    import subprocess
    import sys

    out = tmp_path / "run"
    done = subprocess.run([sys.executable, "-m", "tools.cli", "train", "--recipe", "laps", "--data", str(SAMPLE),
                           "--out", str(out), "--epochs", "2", "--max-steps-per-epoch", "1", "--threads", "1"],
                          capture_output=True, text=True, timeout=300, cwd=Path(__file__).parents[1])
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stderr == ""  # no bars off a terminal, no log lines repeating what is printed
    lines = done.stdout.splitlines()
    assert len(lines) == len(set(lines)), done.stdout
    assert lines[:4] == ["read: 36 rows of 1 recording; 0 bad rows or missing images, 0 unreadable frames",
                         "used: every 2nd row, leaving out 0 below 5 mph: 18 frames",
                         "split: 15 frames for training, 3 held out in blocks of 50",
                         "network: the wider shallow CNN (46,065 weights); 2 epochs of 1 step of 256 samples"]
    assert [line.split(":")[0] for line in lines[4:]] == ["epoch 1/2", "epoch 2/2", "held-out frames", "model",
                                                          "loss curve", "time"]
    assert f"loss curve: {out / 'loss.png'}" in lines
    assert (out / "loss.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.glob(".*.tmp"))
