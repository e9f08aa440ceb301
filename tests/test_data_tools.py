"""``rbc data stats|clean|fetch`` on the real sample, on logs made from it, and against local git repositories."""

from __future__ import annotations

import csv
import datetime as dt
import json
import math
import shutil
import subprocess
import tomllib
from pathlib import Path

import numpy as np
import pytest

from models.data.labels import centred_average
from protocol.datalog import read_log
from protocol.datalog_writer import LogWriter, frame_name, parse_frame_stamp
from protocol.rows import RowRange, keep_rows, parse_rows, row_numbers
from protocol.stamps import frame_time, session_ids
from tests.conftest import UDACITY_SAMPLE
from tools.cli import main
from tools.realdata import recordings
from tools.realdata.recordings import PublicRecording, public_recordings, select
from tools.realdata.stats import INTENT_FRAMES, intent_r, steering_input

REPO = Path(__file__).resolve().parents[1]
needs_git = pytest.mark.skipif(shutil.which("git") is None, reason="needs git")


def _stats(capsys, *dirs: Path, json_out: Path | None = None) -> tuple[list[str], dict | None]:
    argv = ["data", "stats", *map(str, dirs)] + (["--json", str(json_out)] if json_out else [])
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    return lines, json.loads(json_out.read_text()) if json_out else None


def _error(capsys, argv: list[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def _copy(folder: Path, steering=None, speed=None, shift_after: int | None = None, shift_s: float = 0.0,
          repeat_last: bool = False, sides: bool = True) -> Path:
    """A recording made of the sample's frames, renamed to new time stamps (``shift_s`` later from row
    ``shift_after`` on), with relative paths and, optionally, other steering or speeds per row."""
    samples, _ = read_log(UDACITY_SAMPLE)
    (folder / "IMG").mkdir(parents=True)
    with LogWriter(folder / "driving_log.csv") as log:
        for i, s in enumerate(samples + samples[-1:] if repeat_last else samples):
            when = parse_frame_stamp(s.center.name)
            when += dt.timedelta(seconds=shift_s if shift_after is not None and i >= shift_after else 0)
            names = []
            for cam, src in zip(("center", "left", "right"), (s.center, s.left, s.right), strict=True):
                names.append(f"IMG/{frame_name(cam, when)}")
                if cam == "center" or sides:
                    shutil.copy(src, folder / names[-1])
            log.write(names, steering[i] if steering is not None else s.steering, s.throttle, s.brake,
                      speed[i] if speed is not None else s.speed)
    return folder


# --------------------------------------------------------------------------- time stamps, input rule, manifest


def test_frame_times_come_from_the_end_of_the_file_name():
    t = frame_time("center_2016_12_01_13_30_48_287.jpg")
    assert t == (dt.datetime(2016, 12, 1, 13, 30, 48) - dt.datetime(1970, 1, 1)).total_seconds() + 0.287
    assert frame_time(r"C:\x\IMG\my_left_2016_12_01_13_30_48_287.jpg") == t
    assert frame_time("center.jpg") is None and frame_time("center_2016_13_01_13_30_48_287.jpg") is None
    assert session_ids([0.0, 0.1, None, 0.2, 5.0, 5.1, 0.3], gap_s=1.0) == [1, 1, 1, 1, 2, 2, 3]


def test_the_input_rule():
    taps = np.r_[np.zeros(70), np.linspace(-0.5, 0.5, 30)]
    assert steering_input(taps) == "keyboard"  # >= 30 % exactly 0
    grid = np.r_[np.zeros(15), np.round(np.linspace(-1, 1, 85) / 0.05) * 0.05]
    assert steering_input(grid) == "keyboard"  # all on the 0.05 grid, 15 % zeros
    assert steering_input(np.sin(np.linspace(0, 6, 100)) * 0.4 + 0.01) == "mouse"


def test_the_manifest_loads_as_data_and_ships_with_the_package():
    recs = public_recordings()
    assert len(recs) == 42 and len({r.name for r in recs}) == 42
    assert all(isinstance(r, PublicRecording) and r.track in ("lake", "jungle", "mountain") for r in recs)
    assert [len(select(recs, t)) for t in ("lake", "jungle", "mountain")] == [22, 14, 6]
    # #52: two more mountain drives (and a jungle one) looked at, with their quirks
    added = {r.name: r for r in select(recs, names=["b-sh-mountain", "JCLC9027", "b-sh-jungle"])}
    assert added["JCLC9027"].rows == RowRange(1, 1057) and "ROAD CLOSED" in added["JCLC9027"].notes
    assert "stop-and-recover" in added["b-sh-mountain"].notes and added["b-sh-jungle"].track == "jungle"
    split = {r.name: r for r in recs if r.repository == "Ahmedyamani/Track"}
    assert split["Ahmedyamani-lake"].rows == RowRange(1, 2297) and split["Ahmedyamani-mountain"].rows.first == 2298
    assert [r.name for r in select(recs, "jungle") if r.input == "mouse"] == ["TimeToBuzz", "gsyrrakos", "dingchen",
                                                                             "kadway"]
    assert select(recs, names=["808brick"])[0].paths() == ("data/driving_log.csv", "data/IMG")
    # two logs are not named driving_log.csv; two hold Udacity's sample beside the owner's rows
    named = {r.name: r for r in select(recs, names=["kumarSuraj", "kadway", "dingchen"])}
    assert named["kumarSuraj"].paths() == ("driving_log_hard.csv", "IMG") and named["kumarSuraj"].rows is None
    assert named["kadway"].paths() == ("train_data/driving_log_2tracks.csv", "train_data/IMG")
    assert named["kadway"].rows == RowRange(1, 4539)
    assert named["dingchen"].paths() == ("data/driving_log.csv", "data/IMG")
    assert named["dingchen"].rows == RowRange(8035, 13053)  # 3,574 + 1,445 rows of 2020_05_23 and _26
    assert sum(r.log != "driving_log.csv" for r in recs) == 2
    with pytest.raises(ValueError, match="unknown recording"):
        select(recs, names=["nope"])
    data = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert "public_recordings.csv" in data["tools.realdata"]
    assert "tools/realdata/public_recordings.csv" in (REPO / "MANIFEST.in").read_text()
    assert parse_rows("") is None and parse_rows("3-7") == RowRange(3, 7)
    with pytest.raises(ValueError):
        parse_rows("7-3")


def test_the_manifest_log_column_is_optional_and_a_file_name():
    row = {"name": "x", "track": "jungle", "repository": "o/r", "commit": "a" * 40, "folder": "d/", "rows": "",
           "input": "keyboard", "fold": "A"}
    assert recordings._parse(row, 2).paths() == ("d/driving_log.csv", "d/IMG")  # no log column at all
    assert recordings._parse({**row, "log": " "}, 2).log == "driving_log.csv"
    assert recordings._parse({**row, "log": "driving_log_hard.csv"}, 2).paths() == ("d/driving_log_hard.csv", "d/IMG")
    for bad in ("sub/driving_log.csv", r"sub\driving_log.csv", "driving_log.txt"):
        with pytest.raises(ValueError, match="bad entry"):
            recordings._parse({**row, "log": bad}, 2)


def test_a_header_naming_the_columns_out_of_order_is_read_in_the_simulators_order(tmp_path):
    """Ragurajan21's log: header ``...,steering,speed,throttle,brake`` over steering, throttle, brake, speed."""
    samples, _ = read_log(UDACITY_SAMPLE)
    (tmp_path / "IMG").mkdir()
    lines = ["center,left,right,steering,speed,throttle,brake"]
    for s in samples[:3]:
        shutil.copy(s.center, tmp_path / "IMG" / s.center.name)
        lines.append(f"IMG/{s.center.name},,,{s.steering},{s.throttle},{s.brake},{s.speed}")
    (tmp_path / "driving_log.csv").write_text("\n".join(lines) + "\n")
    read, report = read_log(tmp_path)
    assert report.rows == 3 and not report.skipped
    assert [(r.steering, r.throttle, r.brake, r.speed) for r in read] == [(s.steering, s.throttle, s.brake, s.speed)
                                                                          for s in samples[:3]]
    assert read[0].speed == pytest.approx(30.19044)  # mph, not the throttle's 0-1


# --------------------------------------------------------------------------- stats


def test_stats_on_the_real_sample(tmp_path, capsys):
    lines, doc = _stats(capsys, UDACITY_SAMPLE, json_out=tmp_path / "stats.json")
    with (UDACITY_SAMPLE / "driving_log.csv").open(newline="") as fh:
        cells = [[c.strip() for c in row] for row in csv.reader(fh)]
    steering, speed = [float(c[3]) for c in cells], [float(c[6]) for c in cells]
    (rec,) = doc["recordings"]
    assert rec["name"] == "udacity-sample" and rec["rows"] == 36 and rec["rows_with_sides"] == 36
    assert rec["zero_steer_share"] == pytest.approx(sum(v == 0 for v in steering) / 36)
    assert 8.0 < rec["frame_rate_hz"] < 11.0 and rec["sessions"] == 1 and rec["input"] == "keyboard"
    assert (rec["steer_min"], rec["steer_max"]) == (min(steering), max(steering))
    assert (rec["speed_min_mph"], rec["speed_max_mph"]) == (min(speed), max(speed))
    assert rec["creep_share"] == 0 and rec["duplicates"] == 0 and rec["missing_images"] == 0
    assert rec["sharpness"] > 0 and doc["code_version"] and doc["total"]["rows"] == 36
    assert lines[0].split()[:3] == ["recording", "rows", "3-cam"]
    assert lines[2].split()[:3] == ["udacity-sample", "36", "36"] and lines[-1].startswith("total")


def test_stats_tells_a_mouse_driver_and_counts_missing_frames_and_sessions(tmp_path, capsys):
    smooth = [0.3 * math.sin(i / 5) + 0.02 for i in range(36)]
    mouse = _copy(tmp_path / "mouse", steering=smooth, sides=False, shift_after=20, shift_s=5.0)
    keyboard = _copy(tmp_path / "keys", repeat_last=True)
    _, doc = _stats(capsys, mouse, keyboard, json_out=tmp_path / "s.json")
    m, k = doc["recordings"]
    assert (m["input"], k["input"]) == ("mouse", "keyboard") and doc["total"]["input"] == "mixed"
    assert m["rows"] == 36 and m["rows_with_sides"] == 0 and m["missing_images"] == 72 and m["sessions"] == 2
    assert k["rows"] == 37 and k["duplicates"] == 1 and k["sessions"] == 1
    assert doc["total"]["rows"] == 73 and doc["total"]["sessions"] == 3
    # the mouse driver's steering is nearly all intent; the keyboard's taps are mostly not
    assert m["intent_r"] > 0.95 and k["intent_r"] < 0.6
    assert min(k["intent_r"], m["intent_r"]) < doc["total"]["intent_r"] < 1


def test_the_stats_table_fits_100_columns_with_the_columns_the_guide_names():
    """Was 127 characters wide: the documentation's block hid r9, <5mph and dups off the column's edge."""
    from tools.realdata.stats import RecordingStats
    from tools.realdata.table import format_table

    longest = max((r.name for r in public_recordings()), key=len)
    row = RecordingStats(name=longest, rows=14_999, rows_with_sides=14_999, missing_images=1_234, skipped_rows=0,
                         undated_rows=0, frame_rate_hz=14.9, sessions=12, zero_steer_share=0.81, input="keyboard",
                         steer_min=-1.0, steer_max=1.0, abs_steer_p5=0.04, abs_steer_p95=0.35, intent_r=0.31,
                         speed_min_mph=0.0, speed_max_mph=30.2, creep_share=0.12, duplicates=1_234, sharpness=80_511)
    total = RecordingStats(**{**row.as_dict(), "name": "total", "rows": 208_000, "rows_with_sides": 208_000,
                              "input": "mixed"})
    lines = format_table([row] * 39, total).splitlines()
    assert max(map(len, lines)) <= 100
    head = lines[0].split()
    assert {"rows", "missing", "Hz", "r9", "<5mph", "dups"} <= set(head)
    assert lines[2].split()[head.index("r9") - 1] == "0.31"  # "zero %" is one title of two words
    assert lines[-1].split()[:2] == ["total", "208000"]


def test_intent_r_is_the_r_a_model_predicting_the_drivers_average_would_score():
    taps = np.zeros(200)
    taps[::10] = -0.4  # a keyboard driver tapping once a second on a long bend
    average = centred_average(taps, INTENT_FRAMES)
    assert intent_r(taps, average) == pytest.approx(np.corrcoef(taps, average)[0, 1])
    assert intent_r(taps, average) < 0.5
    assert intent_r(np.zeros(10), np.zeros(10)) is None


def test_stats_bad_input_is_one_line(tmp_path, capsys):
    assert "no such file or directory" in _error(capsys, ["data", "stats", str(tmp_path / "nope")])
    (tmp_path / "empty").mkdir()
    assert "driving_log.csv" in _error(capsys, ["data", "stats", str(tmp_path / "empty")])
    garbage = tmp_path / "garbage"
    garbage.mkdir()
    (garbage / "driving_log.csv").write_text("a, b, c, x, 1, 0, 3\n, , , , , ,\nIMG/none.jpg, , , 0, 0, 0, 0\n")
    assert "no usable samples" in _error(capsys, ["data", "stats", str(garbage)])


# --------------------------------------------------------------------------- clean


def test_clean_keeps_rows_speeds_and_first_copies_pointing_at_the_source_frames(tmp_path, capsys):
    speed = [1.0] * 4 + [20.0] * 33  # four creeping rows at the start
    src = _copy(tmp_path / "src", speed=speed, repeat_last=True)  # 37 rows, the last one a repeat
    out = tmp_path / "clean"
    assert main(["data", "clean", str(src), "--out", str(out), "--rows", "2-37", "--min-speed", "5mph",
                 "--drop-duplicates"]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("kept 32 of 37 rows, dropped 0 unusable, 1 outside rows 2-37, 3 below 5 mph, 1 duplicates")
    samples, _ = read_log(out)
    source, _ = read_log(src)
    assert [s.center for s in samples] == [s.center for s in source[4:36]]  # the source frames, not copies
    assert all(s.center.is_absolute() and s.center.parent == (src / "IMG").resolve() for s in samples)
    assert all(s.has_sides for s in samples) and not (out / "IMG").exists()
    first = (out / "driving_log.csv").read_text().splitlines()[0].split(",")
    assert len(first) == 7 and first[0] == str(source[4].center)


def test_clean_splits_sessions_where_the_clock_jumps(tmp_path, capsys):
    src = _copy(tmp_path / "src", shift_after=20, shift_s=5.0)
    out = tmp_path / "sessions"
    assert main(["data", "clean", str(src), "--out", str(out), "--split-sessions"]) == 0
    assert "session-01 (20), session-02 (16)" in capsys.readouterr().out
    first, _ = read_log(out / "session-01")
    second, _ = read_log(out / "session-02")
    assert (len(first), len(second)) == (20, 16) and not (out / "driving_log.csv").exists()
    assert frame_time(second[0].center.name) - frame_time(first[-1].center.name) > 5


def test_clean_rows_count_data_rows_whatever_the_header(tmp_path, capsys):
    src = _copy(tmp_path / "src")
    log = src / "driving_log.csv"
    log.write_text("center,left,right,steering,throttle,brake,speed\n" + log.read_text())
    assert main(["data", "clean", str(src), "--out", str(tmp_path / "out"), "--rows", "1-3"]) == 0
    kept, _ = read_log(tmp_path / "out")
    assert [s.center.name for s in kept] == [s.center.name for s in read_log(src)[0][:3]]
    capsys.readouterr()


def test_clean_refuses_a_non_empty_destination_and_bad_input(tmp_path, capsys):
    src = _copy(tmp_path / "src")
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("keep me")
    assert "not empty" in _error(capsys, ["data", "clean", str(src), "--out", str(out)])
    assert main(["data", "clean", str(src), "--out", str(out), "--force"]) == 0
    assert (out / "mine.txt").read_text() == "keep me" and len(read_log(out)[0]) == 36
    capsys.readouterr()
    assert "source recording" in _error(capsys, ["data", "clean", str(src), "--out", str(src), "--force"])
    assert "--rows" in _error(capsys, ["data", "clean", str(src), "--out", str(tmp_path / "o2"), "--rows", "9-2"])
    assert "no row left" in _error(capsys, ["data", "clean", str(src), "--out", str(tmp_path / "o3"),
                                            "--min-speed", "90mph"])
    assert not (tmp_path / "o3").exists()
    assert "no such file" in _error(capsys, ["data", "clean", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])


# --------------------------------------------------------------------------- fetch


def _git(*args: str, cwd: Path) -> str:
    return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=cwd, check=True,
                          capture_output=True, text=True).stdout.strip()


SAMPLE_ROWS = 36  # rows of the sample's driving_log.csv


def _sample_lines() -> list[str]:
    return (UDACITY_SAMPLE / "driving_log.csv").read_text(encoding="utf-8").splitlines()


@pytest.fixture
def local_repos(tmp_path, monkeypatch) -> tuple[str, Path]:
    """BASE/owner/repo: a commit with data/driving_log.csv and data/IMG/, then one deleting them; the manifest
    is swapped for entries pointing there (one whole, one rows 5-14, one whose repository does not exist).
    The commit also holds two logs as some public recordings have them: other/driving_log_hard.csv (the
    log of that folder; its driving_log.csv is another set of rows) and cr/driving_log.csv (a header row,
    CR-only line ends, rows 1-10 another driver's, 11-36 the recording's)."""
    repo = tmp_path / "base" / "owner" / "repo"
    shutil.copytree(UDACITY_SAMPLE, repo / "data", ignore=shutil.ignore_patterns("README.md"))
    (repo / "model.h5").write_bytes(b"\0" * 100_000)  # what a recording's repository also holds
    lines = _sample_lines()
    shutil.copytree(UDACITY_SAMPLE / "IMG", repo / "other" / "IMG")
    (repo / "other" / "driving_log_hard.csv").write_text("\n".join(lines[:20]) + "\n", encoding="utf-8")
    (repo / "other" / "driving_log.csv").write_text("\n".join(lines[20:]) + "\n", encoding="utf-8")
    shutil.copytree(UDACITY_SAMPLE / "IMG", repo / "cr" / "IMG")
    (repo / "cr" / "driving_log.csv").write_bytes(
        "\r".join(["center,left,right,steering,throttle,brake,speed", *lines]).encode() + b"\r")
    _git("init", "-q", cwd=repo)
    _git("config", "uploadpack.allowFilter", "true", cwd=repo)  # a real partial clone, as from GitHub
    _git("add", "-A", cwd=repo)
    _git("commit", "-qm", "recording", cwd=repo)
    commit = _git("rev-parse", "HEAD", cwd=repo)
    _git("rm", "-rq", "data", cwd=repo)
    _git("commit", "-qm", "gone", cwd=repo)

    def entry(name: str, repository: str, rows: RowRange | None = None, folder: str = "data/",
              log: str = "driving_log.csv") -> PublicRecording:
        return PublicRecording(name, "lake", repository, commit, folder, rows, "keyboard", "A", log)

    entries = [entry("whole", "owner/repo"), entry("part", "owner/repo", RowRange(5, 14)), entry("gone", "owner/none"),
               entry("hard", "owner/repo", folder="other/", log="driving_log_hard.csv"),
               entry("cr", "owner/repo", RowRange(11, SAMPLE_ROWS), folder="cr/")]
    monkeypatch.setattr(recordings, "public_recordings", lambda: entries)
    return f"file://{tmp_path / 'base'}", tmp_path / "fetched"


@needs_git
def test_fetch_checks_out_the_log_and_frames_at_the_commit(local_repos, capsys):
    base, out = local_repos
    argv = ["data", "fetch", "--out", str(out), "--base-url", base, "--name", "whole", "--name", "part"]
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("whole: 36 rows, 108 frames") and lines[1].startswith("part: 10 rows (rows 5-14)")
    assert sorted(p.name for p in (out / "whole").iterdir()) == [".done", "IMG", "driving_log.csv"]
    assert sorted(p.name for p in out.iterdir()) == ["part", "whole"]  # the clones are gone
    assert (out / "whole" / "driving_log.csv").read_bytes() == (UDACITY_SAMPLE / "driving_log.csv").read_bytes()
    part, _ = read_log(out / "part")
    assert [s.center.name for s in part] == [s.center.name for s in read_log(UDACITY_SAMPLE)[0][4:14]]
    assert main(argv) == 0  # complete ones are skipped
    assert all("already complete" in line for line in capsys.readouterr().out.splitlines())


@needs_git
def test_fetch_takes_the_log_the_manifest_names(local_repos, capsys):
    base, out = local_repos
    assert main(["data", "fetch", "--out", str(out), "--base-url", base, "--name", "hard"]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert line.startswith("hard: 20 rows, 108 frames") and " /other/driving_log_hard.csv -> " in line
    assert sorted(p.name for p in (out / "hard").iterdir()) == [".done", "IMG", "driving_log.csv"]
    fetched = (out / "hard" / "driving_log.csv").read_text(encoding="utf-8").splitlines()
    assert fetched == _sample_lines()[:20]  # driving_log_hard.csv, not the folder's driving_log.csv
    samples, report = read_log(out / "hard")
    assert report.rows == 20 and not report.skipped
    assert [s.center.name for s in samples] == [s.center.name for s in read_log(UDACITY_SAMPLE)[0][:20]]


@needs_git
def test_fetch_of_a_cr_only_log_with_a_header_keeps_the_rows_named(local_repos, capsys):
    base, out = local_repos
    assert main(["data", "fetch", "--out", str(out), "--base-url", base, "--name", "cr"]) == 0
    assert capsys.readouterr().out.startswith(f"cr: 26 rows (rows 11-{SAMPLE_ROWS}), 108 frames")
    text = (out / "cr" / "driving_log.csv").read_text(encoding="utf-8")
    assert text.splitlines()[0] == "center,left,right,steering,throttle,brake,speed"  # the header stays
    samples, report = read_log(out / "cr")
    sample, _ = read_log(UDACITY_SAMPLE)
    assert report.rows == 26 and not report.skipped
    assert [s.center.name for s in samples] == [s.center.name for s in sample[10:]]
    assert [s.steering for s in samples] == [s.steering for s in sample[10:]]
    # read as it is in the repository (CR-only, header): the same rows, numbered as rows.py numbers them
    raw = out / "raw.csv"
    raw.write_bytes("\r".join(["center,left,right,steering,throttle,brake,speed", *_sample_lines()]).encode())
    assert list(row_numbers(raw).items())[:2] == [(2, 1), (3, 2)] and len(row_numbers(raw)) == SAMPLE_ROWS
    assert keep_rows(raw, RowRange(11, SAMPLE_ROWS)) == 26
    assert raw.read_text(encoding="utf-8") == text


@needs_git
def test_fetch_of_a_missing_repository_is_one_line_naming_it(local_repos, capsys):
    base, out = local_repos
    err = _error(capsys, ["data", "fetch", "--out", str(out), "--base-url", base, "--name", "gone"])
    assert "owner/none" in err and "1 of 1 recordings not fetched" in err
    assert not out.exists()  # nothing fetched: the new empty output is removed
    assert "unknown recording" in _error(capsys, ["data", "fetch", "--out", str(out), "--name", "nope"])


def test_every_public_recording_is_in_a_fold_and_a_driver_in_one_fold_only() -> None:
    from tools.realdata.recordings import fold_arguments, public_recordings

    recs = public_recordings()
    assert {r.fold for r in recs} == {"A", "B", "C", "D"}
    owner_folds: dict[str, set[str]] = {}
    for r in recs:
        owner_folds.setdefault(r.repository.split("/")[0], set()).add(r.fold)
    assert all(len(f) == 1 for f in owner_folds.values())
    for fold in "ABCD":
        held = [r.track for r in recs if r.fold == fold]
        assert held.count("lake") >= 5 and held.count("jungle") >= 3 and held.count("mountain") >= 1
        assert sum(r.input == "mouse" for r in recs if r.fold == fold) == 1  # the smooth drivers spread out
        args = fold_arguments(recs, "real/", fold)
        assert args.count("--val-data") == sum(r.fold == fold for r in recs) and len(args) == 2 * len(recs)
        assert "real/0xR4Y" in args
