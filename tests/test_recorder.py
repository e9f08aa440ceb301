"""``drive_server --record DIR``: every answered frame and the command sent, as a log the reader reads back;
a full disk, a slow disk or an unwritable folder is reported and counted while the server drives on."""

from __future__ import annotations

import base64
import errno
import threading
from pathlib import Path

import pytest
from helpers_server import SAMPLE_LOG, build_shallow

from drive_server.observing.recorder import Recorder
from protocol import SteerCommand
from protocol.datalog import read_log
from tools.wire.frames import log_frames

FRAMES = log_frames(SAMPLE_LOG)


def test_recorder_writes_a_log_the_reader_reads(tmp_path: Path) -> None:
    rec = Recorder(tmp_path / "rec")
    sent = [SteerCommand(0.01 * i - 0.1, 0.5 - 0.1 * i) for i in range(10)]
    for frame, command in zip(FRAMES, sent, strict=False):
        rec.record(frame.image_b64, command, frame.speed)
    counts = rec.close()
    assert (counts.received, counts.recorded, counts.dropped, counts.failed) == (10, 10, 0, 0)
    samples, report = read_log(tmp_path / "rec")
    assert len(samples) == 10 and not report.skipped
    for s, frame, command in zip(samples, FRAMES, sent, strict=False):
        assert s.center.read_bytes() == base64.b64decode(frame.image_b64)  # the received JPEG, not re-encoded
        assert s.steering == pytest.approx(command.steering, abs=1e-6)
        assert s.throttle == pytest.approx(max(0.0, command.throttle), abs=1e-6)
        assert s.brake == pytest.approx(max(0.0, -command.throttle), abs=1e-6)
        assert s.speed == pytest.approx(frame.speed, abs=1e-4)
    assert len({s.center.name for s in samples}) == 10  # unique names even when written within a millisecond


def test_appending_to_an_existing_recording_keeps_names_unique(tmp_path: Path) -> None:
    for _ in range(2):
        rec = Recorder(tmp_path / "rec")
        for frame in FRAMES[:5]:
            rec.record(frame.image_b64, SteerCommand(0.0, 0.1), frame.speed)
        rec.close()
    samples, _ = read_log(tmp_path / "rec")
    assert len(samples) == 10 and len({s.center for s in samples}) == 10


def test_a_full_disk_is_reported_and_recording_resumes_when_space_returns(tmp_path: Path, monkeypatch,
                                                                         caplog) -> None:
    real = Path.write_bytes
    failures = iter([True, True, True])

    def write_bytes(self, data):  # the first three frames hit a full disk
        if next(failures, False):
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", write_bytes)
    rec = Recorder(tmp_path / "rec")
    for frame in FRAMES[:8]:
        rec.record(frame.image_b64, SteerCommand(0.0, 0.1), frame.speed)  # never raises
    counts = rec.close()
    assert (counts.recorded, counts.failed) == (5, 3)
    assert "No space left on device" in caplog.text and "drives on" in caplog.text
    assert len(read_log(tmp_path / "rec")[0]) == 5


def test_a_slow_disk_drops_and_counts_frames_instead_of_blocking(tmp_path: Path, monkeypatch) -> None:
    release = threading.Event()
    real = Recorder._write

    def slow(self, *item):
        release.wait(10)
        return real(self, *item)

    monkeypatch.setattr(Recorder, "_write", slow)
    rec = Recorder(tmp_path / "rec", queue_frames=2)
    for frame in FRAMES[:12]:
        rec.record(frame.image_b64, SteerCommand(0.0, 0.1), frame.speed)
    assert rec.counts.dropped >= 12 - 3  # two queued, at most one being written
    release.set()
    counts = rec.close()
    assert counts.recorded + counts.dropped == 12 and counts.failed == 0


def test_an_unwritable_folder_is_reported_and_nothing_raises(tmp_path: Path, caplog) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    rec = Recorder(blocker / "rec")
    rec.record(FRAMES[0].image_b64, SteerCommand(0.0, 0.1), 1.0)
    assert rec.close().failed == 1 and "cannot record to" in caplog.text


@pytest.mark.slow
def test_drive_server_records_every_answered_telemetry(tmp_path: Path) -> None:
    pytest.importorskip("onnx")
    from tools.wire.server_process import ServerProcess
    from tools.wire.unity_client import UnityWireClient

    model = build_shallow(tmp_path / "tiny.onnx", seed=1)
    srv = ServerProcess(model, ["--log-every", "0", "--record", str(tmp_path / "rec")])
    srv.start()
    try:
        with UnityWireClient(srv.url) as client:
            replies = []
            for i, frame in enumerate(FRAMES[:20]):
                replies.append(client.exchange(frame.payload())[0])
                if i == 5:
                    assert client.exchange(None)[0] is None  # manual mode: no frame to record
    finally:
        assert srv.stop() == 0, srv.log()
    assert "Traceback" not in srv.log() and "recorded 20 of 20 answered frames" in srv.log()
    samples, report = read_log(tmp_path / "rec")
    assert len(samples) == 20 and not report.skipped
    for s, reply, frame in zip(samples, replies, FRAMES, strict=False):
        assert s.steering == pytest.approx(reply.steering, abs=1e-5)
        assert s.throttle - s.brake == pytest.approx(reply.throttle, abs=1e-5)
        assert s.center.read_bytes() == base64.b64decode(frame.image_b64)


@pytest.mark.slow
def test_drive_server_with_an_unwritable_record_folder_still_drives(tmp_path: Path) -> None:
    pytest.importorskip("onnx")
    from tools.wire.server_process import ServerProcess
    from tools.wire.unity_client import UnityWireClient

    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    model = build_shallow(tmp_path / "tiny.onnx", seed=1)
    srv = ServerProcess(model, ["--log-every", "0", "--record", str(blocker / "rec")])
    srv.start()
    try:
        with UnityWireClient(srv.url) as client:
            assert all(isinstance(client.exchange(f.payload())[0], SteerCommand) for f in FRAMES[:3])
    finally:
        assert srv.stop() == 0, srv.log()
    assert "cannot record to" in srv.log() and "Traceback" not in srv.log()
