"""``rbc video`` and ``rbc sim --video``: one writer, H.264 a browser plays (PyAV), OpenCV mp4v as the fallback."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from protocol.datalog import read_log
from protocol.datalog_writer import LogWriter
from tools.cli import main
from tools.sim.pictures import video as video_mod
from tools.sim.pictures.recording_video import write_recording_video

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"


def _frames_h264(path: Path) -> tuple[str, str, int]:
    av = pytest.importorskip("av")
    with av.open(str(path)) as c:
        stream = c.streams.video[0]
        frames = sum(1 for _ in c.decode(video=0))
        return stream.codec_context.name, stream.codec_context.pix_fmt, frames


def test_rbc_video_writes_h264_a_browser_plays(tmp_path: Path, capsys) -> None:
    if not video_mod.h264_available():
        pytest.skip("PyAV with libx264 is not installed (the video extra)")
    out = tmp_path / "run.mp4"
    assert main(["video", str(SAMPLE), "--out", str(out)]) == 0
    assert _frames_h264(out) == ("h264", "yuv420p", 36)
    assert "36 frames" in capsys.readouterr().out
    assert not list(tmp_path.glob(".*part*"))  # the temporary file was moved into place
    with out.open("rb") as fh:  # +faststart: the index (moov) comes before the frames, as browsers want
        head = fh.read(4096)
    assert head.find(b"moov") != -1 and (head.find(b"mdat") == -1 or head.find(b"moov") < head.find(b"mdat"))


def test_without_pyav_the_fallback_is_said_and_readable(tmp_path: Path, monkeypatch, caplog) -> None:
    monkeypatch.setattr(video_mod, "h264_available", lambda: False)
    summary = write_recording_video(SAMPLE, tmp_path / "run.mp4")
    assert summary.backend == video_mod.MP4V and "browsers" in caplog.text
    assert 'pip install -e ".[video]"' in caplog.text
    cap = cv2.VideoCapture(str(summary.path))
    count = 0
    while cap.read()[0]:
        count += 1
    assert count == 36


def test_a_pause_in_the_frames_is_marked_as_an_intervention(tmp_path: Path) -> None:
    samples, _ = read_log(SAMPLE)
    rec = tmp_path / "rec"
    (rec / "IMG").mkdir(parents=True)
    import datetime as dt

    from protocol.datalog_writer import frame_name

    t0 = dt.datetime(2026, 1, 1, 12, 0, 0)
    with LogWriter(rec / "driving_log.csv") as w:
        for i, s in enumerate(samples[:20]):
            t = t0 + dt.timedelta(seconds=i / 15 + (3.0 if i >= 10 else 0.0))  # 3 s without frames after frame 9
            name = rec / "IMG" / frame_name("center", t)
            shutil.copy(s.center, name)
            w.write([str(name)], s.steering, 0.3, 0.0, 20.0)
    summary = write_recording_video(rec, tmp_path / "v.mp4")
    assert summary.interventions == 1 and summary.frames == 20 and summary.fps == pytest.approx(15, rel=0.05)


def test_rbc_sim_video_uses_the_same_writer(tmp_path: Path) -> None:
    from tools.sim.pictures.viz import VideoRecorder

    rec = VideoRecorder(tmp_path / "lap.mp4", 15)
    assert isinstance(rec._writer, video_mod.VideoWriter) and rec.backend in (video_mod.H264, video_mod.MP4V)
    rec._writer.write(np.zeros((160, 320, 3), np.uint8))
    rec.close()
    assert (tmp_path / "lap.mp4").stat().st_size > 0


def test_an_empty_recording_leaves_no_video(tmp_path: Path, capsys) -> None:
    assert main(["video", str(tmp_path / "nope"), "--out", str(tmp_path / "x.mp4")]) == 2
    assert "no such file or directory" in capsys.readouterr().err and not (tmp_path / "x.mp4").exists()
