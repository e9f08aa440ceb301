"""The tolerant driving-log reader on real Udacity data and on malformed logs."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from protocol.datalog import DataLogError, read_log, read_logs

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
FRAMES = sorted((SAMPLE / "IMG").glob("center_*.jpg"))


def _recording(tmp_path: Path, lines: list[str], name: str = "driving_log.csv", img_dir: str = "IMG",
               frames: int = 4) -> tuple[Path, list[str]]:
    """A recording folder with ``frames`` copies of real frames as c<i>.jpg, l<i>.jpg, r<i>.jpg."""
    img = tmp_path / img_dir
    img.mkdir(parents=True, exist_ok=True)
    names = []
    for i in range(frames):
        for cam in "clr":
            shutil.copy(FRAMES[i], img / f"{cam}{i}.jpg")
        names.append(f"c{i}.jpg")
    (tmp_path / name).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return tmp_path, names


def test_real_udacity_sample_with_windows_paths() -> None:
    samples, report = read_log(SAMPLE)
    assert len(samples) == 36 and report.used == 36 and not report.skipped
    first = samples[0]
    assert first.center == (SAMPLE / "IMG" / "center_2020_05_09_22_17_04_872.jpg").resolve()
    assert first.left is not None and first.left.name == "left_2020_05_09_22_17_04_872.jpg"
    assert first.right is not None and first.right.name.startswith("right_")
    assert first.has_sides
    assert (first.steering, first.throttle, first.brake) == (0.0, 1.0, 0.0)
    assert first.speed == pytest.approx(30.19044)
    assert samples[2].steering == pytest.approx(-0.2095149)
    assert [s.line for s in samples] == list(range(1, 37))
    assert all(s.log == (SAMPLE / "driving_log.csv").resolve() for s in samples)


def test_header_relative_posix_and_exponent_numbers(tmp_path: Path) -> None:
    rec, _ = _recording(tmp_path, [
        "center,left,right,steering,throttle,brake,speed",
        "IMG/c0.jpg, IMG/l0.jpg, IMG/r0.jpg, 7.8E-05, 0, 0, 7.843922E-05",
        "/home/someone/else/IMG/c1.jpg,/home/someone/else/IMG/l1.jpg,/home/someone/else/IMG/r1.jpg,-0.25,0.5,0,30",
        r"D:\rec\IMG\c2.jpg, D:\rec\IMG\l2.jpg, D:\rec\IMG\r2.jpg, 1, 1, 0, 29.9",
    ])
    samples, report = read_log(rec / "driving_log.csv")
    assert report.rows == 3 and not report.skipped
    assert [s.steering for s in samples] == pytest.approx([7.8e-05, -0.25, 1.0])
    assert samples[0].speed == pytest.approx(7.843922e-05)
    assert [s.center.name for s in samples] == ["c0.jpg", "c1.jpg", "c2.jpg"]
    assert all(s.center.parent == (rec / "IMG").resolve() for s in samples)
    assert [s.line for s in samples] == [2, 3, 4]


def test_missing_images_and_bad_numbers_are_reported_and_skipped(tmp_path: Path,
                                                                  caplog: pytest.LogCaptureFixture) -> None:
    rec, _ = _recording(tmp_path, [
        "IMG/c0.jpg, IMG/l0.jpg, IMG/r0.jpg, 0.1, 0, 0, 1",
        "IMG/missing.jpg, IMG/l1.jpg, IMG/r1.jpg, 0.1, 0, 0, 1",
        "IMG/c1.jpg, IMG/l1.jpg, IMG/gone.jpg, 0.1, 0, 0, 1",
        "IMG/c2.jpg, IMG/l2.jpg, IMG/r2.jpg, 0.1, 0, 0, 1",
        "IMG/c3.jpg, IMG/l3.jpg, IMG/r3.jpg, 0.2, 0,, 1",
        "IMG/c3.jpg, IMG/l3.jpg, IMG/r3.jpg, 3.5, 0, 0, 1",
        "IMG/c3.jpg, IMG/l3.jpg",
        "IMG/c3.jpg, IMG/l3.jpg, IMG/r3.jpg, abc, 0, 0, 1",
    ])
    (rec / "IMG" / "c2.jpg").write_bytes(b"not a jpeg at all")
    samples, report = read_log(rec)
    assert [s.line for s in samples] == [1, 3, 5]
    assert samples[2].brake == 0.0  # empty optional number
    skipped = {s.line: s.reason for s in report.skipped}
    assert sorted(skipped) == [2, 4, 6, 7, 8]
    assert skipped[2].startswith("missing image") and "missing.jpg" in skipped[2]
    assert skipped[4].startswith("unreadable image") and "c2.jpg" in skipped[4]
    assert skipped[6].startswith("bad number") and "outside" in skipped[6]
    assert skipped[8] == "bad number: steering 'abc'"
    # a missing side frame costs the row its sides, not the row (was: skipped as "missing image")
    assert samples[1].left is None and samples[1].right is None and not samples[1].has_sides
    assert [(s.line, s.reason.split(":")[0]) for s in report.side_losses] == [(3, "missing image")]
    assert "gone.jpg" in report.side_losses[0].reason and report.rows_without_sides == 1
    assert "5 of 8 rows skipped" in report.summary() and "1 rows used without side frames" in report.summary()
    assert any("rows skipped" in r.getMessage() for r in caplog.records)


def test_missing_or_unreadable_side_frames_leave_the_row_without_sides(tmp_path: Path) -> None:
    rec, _ = _recording(tmp_path, [
        "IMG/c0.jpg, IMG/gone.jpg, IMG/r0.jpg, 0.1, 0, 0, 1",
        "IMG/c1.jpg, IMG/l1.jpg, IMG/r1.jpg, 0.2, 0, 0, 1",
        "IMG/c2.jpg, IMG/l2.jpg, IMG/r2.jpg, 0.3, 0, 0, 1",
        "IMG/gone.jpg, IMG/l3.jpg, IMG/r3.jpg, 0.4, 0, 0, 1",
        "IMG/c3.jpg, IMG/gone.jpg, IMG/r3.jpg, 0.5, 0, 0, fast",
    ])
    (rec / "IMG" / "r2.jpg").write_bytes(b"not a jpeg")
    samples, report = read_log(rec)
    assert [(s.line, s.has_sides, s.left is None, s.right is None) for s in samples] == [
        (1, False, True, True), (2, True, False, False), (3, False, True, True)]
    assert [(s.line, s.reason.split(":")[0]) for s in report.side_losses] == [(1, "missing image"),
                                                                              (3, "unreadable image")]
    assert [s.line for s in report.skipped] == [4, 5]  # a missing centre frame still skips the row


def test_one_camera_logs(tmp_path: Path) -> None:
    rec, _ = _recording(tmp_path, [
        "IMG/c0.jpg, , , -0.5, 0.3, 0, 20",
        "IMG/c1.jpg, -0.25, 0.3, 0, 20",  # five columns: no side fields at all
    ])
    samples, report = read_log(rec)
    assert len(samples) == 2 and not report.skipped
    assert all(s.left is None and s.right is None and not s.has_sides for s in samples)
    assert [s.steering for s in samples] == [-0.5, -0.25]


def test_paper_layout_driving_log_and_camera_frames(tmp_path: Path) -> None:
    rec, _ = _recording(tmp_path, [
        r"C:\Users\x\Dataset\Camera-Frames\c0.jpg,C:\Users\x\Dataset\Camera-Frames\l0.jpg,"
        r"C:\Users\x\Dataset\Camera-Frames\r0.jpg,0.04,0.5,0,29.8",
    ], name="Driving-Log.csv", img_dir="Camera-Frames")
    samples, _ = read_log(rec)
    assert samples[0].center == (rec / "Camera-Frames" / "c0.jpg").resolve()


def test_empty_and_unusable_logs_are_clear_errors(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "driving_log.csv").write_text("", encoding="utf-8")
    with pytest.raises(DataLogError, match="no usable samples"):
        read_log(empty)
    header_only = tmp_path / "header"
    header_only.mkdir()
    (header_only / "driving_log.csv").write_text("center,left,right,steering,throttle,brake,speed\n")
    with pytest.raises(DataLogError, match="no usable samples"):
        read_log(header_only)
    broken, _ = _recording(tmp_path / "broken", ["IMG/nothere.jpg, , , 0, 0, 0, 0"])
    with pytest.raises(DataLogError, match="missing image"):
        read_log(broken)
    with pytest.raises(DataLogError, match="no such file"):
        read_log(tmp_path / "does-not-exist")
    (tmp_path / "nolog").mkdir()
    with pytest.raises(DataLogError, match="driving_log.csv"):
        read_log(tmp_path / "nolog")


def test_several_logs_combine(tmp_path: Path) -> None:
    other, _ = _recording(tmp_path / "b", ["IMG/c0.jpg, IMG/l0.jpg, IMG/r0.jpg, 0.5, 1, 0, 30"])
    data = read_logs([SAMPLE, other])
    assert len(data.samples) == 37
    assert data.samples[-1].log == (other / "driving_log.csv").resolve()
    assert [r.used for r in data.reports] == [36, 1]
    with pytest.raises(DataLogError):
        read_logs([])


def test_writer_rows_read_back_with_the_reader(tmp_path: Path) -> None:
    """One column layout: what the writer writes, the reader reads (numbers as C# prints them)."""
    import datetime as dt

    from protocol.datalog_writer import (
        IMAGE_DIR,
        LOG_NAME,
        LogWriter,
        format_number,
        frame_name,
        last_row_stamp,
        parse_frame_stamp,
    )

    when = dt.datetime(2020, 5, 9, 22, 17, 4, 872000)
    (tmp_path / IMAGE_DIR).mkdir()
    jpeg = FRAMES[0].read_bytes()
    with LogWriter(tmp_path / LOG_NAME) as writer:
        for k in range(3):
            t = when + dt.timedelta(seconds=k / 15)
            paths = [tmp_path / IMAGE_DIR / frame_name(cam, t) for cam in ("center", "left", "right")]
            for path in paths:
                path.write_bytes(jpeg)
            writer.write([str(p) for p in paths], -0.2095149 * k, 0.5, 7.843922e-05, 30.0 / 1.609344)
    text = (tmp_path / LOG_NAME).read_text()
    assert ", " in text and "E-05" in text and text.count("\n") == 3
    samples, report = read_log(tmp_path)
    assert report.used == 3 and not report.skipped
    assert [round(s.steering, 6) for s in samples] == [0.0, -0.209515, -0.41903]
    assert samples[0].has_sides and samples[2].brake == pytest.approx(7.843922e-05)
    assert last_row_stamp(tmp_path / LOG_NAME) == when + dt.timedelta(milliseconds=1000 * 2 // 15)
    assert parse_frame_stamp(frame_name("left", when)) == when
    assert format_number(0.0) == "0" and format_number(-0.5) == "-0.5"
