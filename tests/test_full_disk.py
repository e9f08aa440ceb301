"""Full disks, for real: a small tmpfs filled with ballast under recording, rbc collect, rbc train and rbc eval.

Each job must keep what it wrote before (no half row, no cut-off image, no torn checkpoint or journal
line), stop with one clear line (the drive loop keeps answering), and ``--resume`` must finish, once space
is back, with what an uninterrupted run gives. Needs a mount (root); skipped with the reason otherwise.
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import time
from pathlib import Path

import cv2
import pytest
from helpers_server import SAMPLE_LOG, build_shallow
from test_rules import stadium

from protocol import SteerCommand
from protocol.datalog import read_log
from tests.conftest import write_stadium
from tools.cli import main
from tools.wire.frames import log_frames
from tools.wire.server_process import ServerProcess
from tools.wire.unity_client import UnityWireClient

NO_SPACE = "no space left on device"


class SmallDisk:
    """A tmpfs of ``size`` at ``path``; ``fill(leave)`` takes all but ``leave`` bytes, ``free()`` gives it back."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.ballast = path / ".ballast"

    def fill(self, leave: int = 0) -> None:
        chunk = b"\0" * (1 << 16)
        with self.ballast.open("ab") as fh:
            try:
                while True:
                    fh.write(chunk)
                    fh.flush()
            except OSError as exc:
                assert exc.errno == errno.ENOSPC
        if leave:
            size = self.ballast.stat().st_size
            os.truncate(self.ballast, max(0, size - leave))

    def free(self) -> None:
        self.ballast.unlink(missing_ok=True)


@pytest.fixture
def small_disk(tmp_path):
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(mount)], capture_output=True,
                          text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a small file system here: {done.stderr.strip() or done.returncode}")
    try:
        yield SmallDisk(mount)
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


def _every_row_whole(folder: Path) -> int:
    """Rows of the log in ``folder``, each with all its images decodable; no image without a row."""
    text = (folder / "driving_log.csv").read_text(encoding="utf-8")
    assert text == "" or text.endswith("\n"), "the log ends in half a row"
    samples, report = read_log(folder)
    assert not report.skipped, report.summary()
    named = set()
    for s in samples:
        for image in (s.center, s.left, s.right):
            if image is not None:
                assert cv2.imread(str(image)) is not None, f"{image} is cut off"
                named.add(Path(image).name)
    on_disk = {p.name for p in (folder / "IMG").iterdir()}
    assert on_disk == named, f"images without a row: {sorted(on_disk - named)[:3]}"
    return len(samples)


def _one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1 and "Traceback" not in err, err[-2000:]
    return lines[0]


# ------------------------------------------------------------------------------------------------ the log writer
def test_a_log_row_the_disk_takes_only_part_of_is_cut_back(small_disk):
    """Was: the buffered writer left the first half of the row that hit the full disk (the file ended
    mid-row, and the next append after freeing space glued a row onto it)."""
    from protocol.datalog_writer import LogWriter

    small_disk.fill(leave=10_000)
    writer = LogWriter(small_disk.path / "driving_log.csv")
    with pytest.raises(OSError) as info:
        for _ in range(10_000):
            writer.write([f"{small_disk.path}/IMG/center_2020_01_01_12_00_00_000.jpg"], 0.1, 0.2, 0.0, 17.5)
    assert info.value.errno == errno.ENOSPC
    text = (small_disk.path / "driving_log.csv").read_text()
    assert text.endswith("\n") and len(text.splitlines()) == writer.rows > 0
    small_disk.free()
    writer.write([f"{small_disk.path}/IMG/center_2020_01_01_12_00_01_000.jpg"], 0.1, 0.2, 0.0, 17.5)
    writer.close()
    lines = (small_disk.path / "driving_log.csv").read_text().splitlines()
    assert len(lines) == writer.rows and all(line.count(", ") == 6 for line in lines)


# ------------------------------------------------------------------------------------------------ rbc collect
def test_collect_stops_with_one_line_keeps_its_rows_and_resume_ends_as_a_clean_run(small_disk, tmp_path, capsys):
    track = stadium(tmp_path, straight=30.0, radius=16.0)
    flags = ["collect", "--track", track, "--rate-hz", "6", "--cameras", "3"]
    assert main([*flags, "--out", str(tmp_path / "clean")]) == 0
    clean_rows = _every_row_whole(tmp_path / "clean")
    capsys.readouterr()

    out = small_disk.path / "c"
    small_disk.fill(leave=300_000)  # room for about a third of the data set
    assert main([*flags, "--out", str(out)]) == 2
    assert NO_SPACE in _one_error_line(capsys.readouterr().err)
    kept = _every_row_whole(out)
    assert 0 < kept < clean_rows

    small_disk.free()
    assert main([*flags, "--out", str(out), "--resume"]) == 0
    assert _every_row_whole(out) == clean_rows
    resumed = (out / "driving_log.csv").read_text().replace(str(out.resolve()), "DIR")
    assert resumed == (tmp_path / "clean" / "driving_log.csv").read_text().replace(
        str((tmp_path / "clean").resolve()), "DIR")
    for image in (tmp_path / "clean" / "IMG").iterdir():
        assert (out / "IMG" / image.name).read_bytes() == image.read_bytes(), image.name


def test_collect_resume_refuses_a_log_written_with_other_settings(tmp_path, capsys):
    track = stadium(tmp_path, straight=30.0, radius=16.0)
    flags = ["collect", "--track", track, "--rate-hz", "6", "--cameras", "1", "--out", str(tmp_path / "c")]
    assert main(flags) == 0
    assert main([*flags, "--seed", "5", "--resume"]) == 2
    assert "is not what this configuration records" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------ recording
def test_recording_on_a_full_disk_drives_on_keeps_whole_rows_and_records_again_once_space_returns(small_disk,
                                                                                                 tmp_path):
    frames = log_frames(SAMPLE_LOG)
    rec = small_disk.path / "rec"
    model = build_shallow(tmp_path / "m.onnx")
    with ServerProcess(model, ["--log-every", "0", "--record", str(rec)]) as srv:
        with UnityWireClient(srv.url) as client:
            for f in frames[:10]:
                assert isinstance(client.exchange(f.payload())[0], SteerCommand)
            time.sleep(0.5)  # written
            small_disk.fill(leave=40_000)
            for k in range(80):  # the disk fills up under the recorder; every frame is still answered
                assert isinstance(client.exchange(frames[k % len(frames)].payload())[0], SteerCommand)
            time.sleep(0.5)
            assert "No space left on device" in srv.log() and "the server drives on" in srv.log()
            small_disk.free()
            for f in frames[:10]:
                assert isinstance(client.exchange(f.payload())[0], SteerCommand)
            time.sleep(0.5)
        assert srv.stop() == 0
        log_text = srv.log()
    assert "Traceback" not in log_text
    rows = _every_row_whole(rec)
    assert 20 <= rows < 100  # some frames were lost to the full disk, the last ten were recorded again
    assert log_text.count("No space left on device") <= 3  # one line per few seconds, not one per frame


# ------------------------------------------------------------------------------------------------ rbc train
def test_train_stops_on_a_full_disk_keeps_its_last_checkpoint_and_resume_ends_as_a_clean_run(small_disk, tmp_path,
                                                                                            monkeypatch, capsys):
    pytest.importorskip("torch")
    import models.training.train as train_mod
    from models.networks.checkpoint import save_checkpoint
    from models.networks.runfiles import read_history

    flags = ["train", "--data", str(SAMPLE_LOG), "--epochs", "3", "--max-steps-per-epoch", "3", "--threads", "1",
             "--no-progress", "--seed", "3"]
    assert main([*flags, "--out", str(tmp_path / "clean")]) == 0
    clean = read_history(tmp_path / "clean" / "history.csv")

    saved = []

    def save_then_fill(path, *args, **kwargs):  # the disk fills up after the first epoch's checkpoint
        save_checkpoint(path, *args, **kwargs)
        saved.append(path)
        if len(saved) == 1:
            small_disk.fill()

    run = small_disk.path / "run"
    with monkeypatch.context() as m:
        m.setattr(train_mod, "save_checkpoint", save_then_fill)
        capsys.readouterr()
        assert main([*flags, "--out", str(run)]) == 2
    assert NO_SPACE in _one_error_line(capsys.readouterr().err)
    checkpoint = run / "checkpoint.pt"
    import torch

    assert torch.load(checkpoint, weights_only=False)["state"]["epoch"] == 1  # the last good one, whole
    assert not [p for p in run.iterdir() if p.name.endswith(".tmp")]

    small_disk.free()
    assert main(["train", "--resume", "--out", str(run), "--no-progress"]) == 0
    resumed = read_history(run / "history.csv")
    assert [h.train_loss for h in resumed] == pytest.approx([h.train_loss for h in clean], rel=1e-6)
    assert [h.val_loss for h in resumed] == pytest.approx([h.val_loss for h in clean], rel=1e-6)


# ------------------------------------------------------------------------------------------------ rbc eval
def test_eval_stops_on_a_full_disk_keeps_whole_journal_lines_and_resume_gives_the_clean_table(small_disk,
                                                                                             tmp_path, capsys):
    from drive_server.serving.models_dir import demo_model_path

    track = write_stadium(tmp_path, straight=60.0, radius=30.0, road_width=10.0)
    flags = ["eval", "--model", str(demo_model_path()), "--track", track, "--experiments", "no_variation",
             "--seeds", "8", "--workers", "1"]
    assert main([*flags, "--out", str(tmp_path / "clean")]) == 0
    clean_runs = (tmp_path / "clean" / "runs.jsonl").read_text().splitlines()
    out = small_disk.path / "ev"
    out.mkdir()
    small_disk.fill(leave=6_000)  # the journal's first lines fit, then the disk is full
    capsys.readouterr()
    assert main([*flags, "--out", str(out)]) == 2
    assert NO_SPACE in _one_error_line(capsys.readouterr().err)
    journal = (out / "runs.jsonl").read_text() if (out / "runs.jsonl").exists() else ""
    kept = [json.loads(line) for line in journal.splitlines()]  # every line whole
    assert journal == "" or journal.endswith("\n")
    assert len(kept) < len(clean_runs)
    small_disk.free()
    assert main([*flags, "--out", str(out), "--resume"]) == 0
    assert (out / "table9.md").read_text() == (tmp_path / "clean" / "table9.md").read_text()
