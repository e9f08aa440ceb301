"""``rbc drive-log`` (issue 22): the closed loop on recorded frames must tell drivers apart, and its view
synthesis must be geometry, not decoration."""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from protocol.jpeg import read_jpeg_file
from tools.cli import main
from tools.drivelog.camera import UnityCamera, ViewSynthesizer, view_homographies
from tools.drivelog.path import advance, curvature

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"


def _curve_log(tmp_path: Path, steering: float = 0.3, speed_mph: float = 20.0) -> Path:
    """The sample's frames (and time stamps) with the steering of one long constant curve."""
    out = tmp_path / "curve"
    shutil.copytree(SAMPLE, out)
    rows = list(csv.reader((out / "driving_log.csv").open(newline=""), skipinitialspace=True))
    with (out / "driving_log.csv").open("w", newline="") as fh:
        for r in rows:
            csv.writer(fh).writerow([*r[:3], steering, 0.5, 0.0, speed_mph])
    return out


def test_not_moving_the_camera_shows_the_recorded_frame() -> None:
    frame = read_jpeg_file(next((SAMPLE / "IMG").glob("center_*.jpg")))
    assert np.array_equal(ViewSynthesizer().view(frame, 0.0, 0.0), frame)


def test_turning_right_moves_the_far_scenery_left_by_f_tan_psi() -> None:
    cam = UnityCamera()
    _, far = view_homographies(cam, 0.0, math.radians(2.0))
    p = far @ np.array([160.0, 40.0, 1.0])
    assert p[0] / p[2] == pytest.approx(160 + cam.focal_px * math.tan(math.radians(2.0)), abs=0.5)


def test_a_camera_moved_right_sees_the_road_shifted_left() -> None:
    cam = UnityCamera()
    ground, _ = view_homographies(cam, 0.5, 0.0)  # new view pixel -> recorded pixel
    row = 120.0  # on the road: ground distance d = h / tan(angle below the horizon)
    d = cam.height_m / math.tan(math.radians(cam.pitch_deg) + math.atan((row - 80) / cam.focal_px))
    p = ground @ np.array([160.0, row, 1.0])
    # the new centre pixel looks at the ground point 0.5 m right of the recorded camera's centre line
    assert p[0] / p[2] > 160 and p[1] / p[2] == pytest.approx(row, abs=0.5)
    assert (p[0] / p[2] - 160) == pytest.approx(cam.focal_px * 0.5 / math.hypot(d, cam.height_m), rel=0.15)


def test_a_driver_steering_as_the_path_stays_on_it_and_a_straight_one_leaves_a_curve() -> None:
    k = float(curvature(0.3))
    on, off = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    for _ in range(30):
        on = advance(*on, 7.0, 0.1, k, k)
        off = advance(*off, 7.0, 0.1, 0.0, k)
    assert on[1:] == (0.0, 0.0) and on[0] == pytest.approx(21.0)
    assert off[1] < -1.0  # the curve turns right; going straight leaves it to the left


@pytest.mark.parametrize(("driver", "passes"), [
    (["--baseline", "recorded"], True),
    (["--baseline", "zero"], False),
    (["--baseline", "recorded", "--steer-bias", "0.3"], False),
])
def test_the_measure_discriminates(tmp_path: Path, driver: list[str], passes: bool) -> None:
    data = _curve_log(tmp_path)
    out = tmp_path / "result.json"
    rc = main(["drive-log", "--data", str(data), *driver, "--wheelbase", "2.6", "--json", str(out),
               "--strip", str(tmp_path / "strip.jpg"), "--plot", str(tmp_path / "offset.png")])
    assert rc == 0
    record = json.loads(out.read_text())
    assert {"eta", "interventions", "offset_rms_m", "frames"} <= set(record)
    assert record["frames"] == 36 and record["rules"]["wheelbase_m"] == 2.6
    if passes:
        assert record["eta"] >= 99.0 and record["interventions"] == 0 and record["offset_rms_m"] == 0.0
    else:
        assert record["interventions"] >= 1 and record["eta"] < 50.0
    assert (tmp_path / "strip.jpg").stat().st_size > 1000 and (tmp_path / "offset.png").stat().st_size > 1000


def test_each_take_over_gets_a_picture_of_the_seconds_before_it(tmp_path: Path, capsys) -> None:
    # issue 52: sorting take-overs into the model's faults and the measure's needs the views before each one
    import cv2

    from protocol.datalog import read_log
    from tools.drivelog.loop import LoopRules, drive
    from tools.drivelog.path import recorded_drive
    from tools.drivelog.pictures import write_takeover_strips

    data = _curve_log(tmp_path)
    takeovers = tmp_path / "takeovers"
    assert main(["drive-log", "--data", str(data), "--baseline", "zero", "--wheelbase", "2.6", "--lane", "path",
                 "--handback", "0", "--strip", str(tmp_path / "s.jpg"), "--plot", str(tmp_path / "p.png"),
                 "--takeovers", str(takeovers)]) == 0
    pictures = sorted(takeovers.glob("takeover-*.jpg"))
    out = capsys.readouterr().out
    takes = int(out.split("take-overs ")[1].split()[0])
    assert takes >= 1 and len(pictures) == takes and f"take-overs {takes} picture(s) in {takeovers}" in out
    sheet = cv2.imread(str(pictures[0]))
    log = recorded_drive(read_log(data)[0])
    h, w = read_jpeg_file(log.frames[0]).shape[:2]
    assert sheet.shape[0] == 2 * h and sheet.shape[1] % w == 0  # the car's views above the driver's frames
    rules = LoopRules(lane="path", wheelbase_m=2.6, handback_s=0.0)
    kept = drive(log, lambda view, i: 0.0, rules, snapshots=0, history_s=1.0)
    assert len(kept.before_takeovers) == kept.interventions >= 1
    times = np.concatenate([[0.0], np.cumsum(log.dt[:-1])])
    for take, views in zip(kept.takeovers, kept.before_takeovers, strict=True):
        assert views and views[-1].takeover and views[-1].step == take.frame  # ends at the take-over's view
        assert all(times[take.frame] - times[v.step] <= 1.0 + 1e-9 for v in views)  # none older than 1 s
    assert drive(log, lambda view, i: 0.0, rules, snapshots=0).before_takeovers == []  # kept only when asked
    with pytest.raises(ValueError, match="history_s"):
        write_takeover_strips(drive(log, lambda view, i: 0.0, rules, snapshots=0), log, tmp_path / "none")


def test_a_model_drives_through_the_serving_pipeline(tmp_path: Path) -> None:
    model = Path(__file__).resolve().parents[1] / "models" / "pretrained" / "simplistic.onnx"
    out = tmp_path / "r.json"
    assert main(["drive-log", "--data", str(_curve_log(tmp_path)), "--model", str(model), "--wheelbase", "2.6",
                 "--json", str(out), "--strip", str(tmp_path / "s.jpg"), "--plot", str(tmp_path / "p.png")]) == 0
    record = json.loads(out.read_text())
    assert record["driver"] == "simplistic.onnx" and 0.0 <= record["eta"] <= 100.0


@pytest.mark.parametrize("argv", [
    ["drive-log", "--data", "/nonexistent/recording", "--baseline", "zero"],
    ["drive-log", "--data", str(SAMPLE)],
    ["drive-log", "--data", str(SAMPLE), "--baseline", "zero", "--max-offset", "0"],
    ["drive-log", "--data", str(SAMPLE), "--model", __file__],
])
def test_bad_input_is_one_line(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("rbc drive-log: error") and "\n" not in err and "Traceback" not in err


@pytest.mark.slow
def test_calibration_finds_the_side_cameras_on_their_sides(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["drive-log", "--data", str(SAMPLE), "--calibrate", "--calibrate-rows", "8"]) == 0
    rows = {line.split()[0]: line.split() for line in capsys.readouterr().out.splitlines()[1:]
            if line.split() and line.split()[0] in ("left", "right")}
    assert float(rows["left"][3]) < -0.2 and float(rows["right"][3]) > 0.2
    assert 2.0 < float(rows["left"][2]) < 12.0


def test_a_person_drives_the_time_a_takeover_costs_before_handing_back(tmp_path: Path) -> None:
    """Eq. 2 charges 6 s per take-over: the time a person drives. Handing back at once (DAVE-2's simulator)
    charged a spot the driver cannot pass again every few frames."""
    data = _curve_log(tmp_path, speed_mph=10.0)
    records = {}
    for handback in ("0", "6"):
        out = tmp_path / f"r{handback}.json"
        assert main(["drive-log", "--data", str(data), "--baseline", "zero", "--lane", "path", "--max-offset", "0.3",
                     "--wheelbase", "2.6", "--handback", handback, "--json", str(out), "--strip",
                     str(tmp_path / "s.jpg"), "--plot", str(tmp_path / "p.png")]) == 0
        records[handback] = json.loads(out.read_text())
    at_once, after = records["0"], records["6"]
    assert at_once["rules"]["handback_s"] == 0 and after["rules"]["handback_s"] == 6
    times = [t["time_s"] for t in after["takeovers"]]
    assert at_once["interventions"] >= 3 and 1 <= after["interventions"] < at_once["interventions"]
    assert np.all(np.diff(times) >= 6.0)
    assert after["driving_time_s"] == pytest.approx(at_once["driving_time_s"], rel=0.1)


def test_the_loop_rules_check_their_own_ranges() -> None:
    """Was: rbc drive-log checked --max-offset, --handback, --speed-limit and --wheelbase itself, rbc data crossval
    --max-offset itself and the hand-back time through the rules: three places for one set of rules."""
    from protocol.errors import BadValue
    from tools.drivelog.loop import LoopRules

    for field, value, flag in [("max_offset_m", 0.0, "--max-offset"), ("handback_s", 61.0, "--handback"),
                               ("speed_limit_kmh", 301.0, "--speed-limit"), ("wheelbase_m", 0.5, "--wheelbase"),
                               ("max_offset_m", math.nan, "--max-offset")]:
        with pytest.raises(BadValue, match=f"^{flag} must be"):
            LoopRules(**{field: value})
    LoopRules(max_offset_m=0.05, handback_s=0.0, speed_limit_kmh=0.0, wheelbase_m=20.0)  # the ends are allowed


@pytest.mark.parametrize("argv", [
    ["drive-log", "--data", str(SAMPLE), "--baseline", "zero", "--handback", "61"],
    ["data", "crossval", "--models", "m-{fold}.onnx", "--name", "0xR4Y", "--handback", "61"],
])
def test_both_commands_refuse_bad_rules_with_the_rules_own_words(argv: list[str], capsys) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"rbc {argv[0]}: error: --handback must be 0..60 seconds, got 61"


def test_drive_log_crossval_and_the_road_go_through_one_assembly(tmp_path: Path, monkeypatch) -> None:
    """Was: the closed loop on a recording was put together three times (rbc drive-log, rbc data crossval, rbc data
    road: driver, wheelbase, road, loop); now tools.drivelog.run does it for all of them."""
    from tools.drivelog import run
    from tools.realdata.crossval import _closed_loop

    calls: list[str] = []
    real_drive, real_road = run.drive_recording, run.car_and_road
    monkeypatch.setattr(run, "drive_recording", lambda *a, **k: calls.append("drive") or real_drive(*a, **k))
    monkeypatch.setattr(run, "car_and_road", lambda *a, **k: calls.append("road") or real_road(*a, **k))
    data = _curve_log(tmp_path)
    model = Path(__file__).resolve().parents[1] / "models" / "pretrained" / "simplistic.onnx"
    out = tmp_path / "r.json"
    assert main(["drive-log", "--data", str(data), "--model", str(model), "--json", str(out),
                 "--strip", str(tmp_path / "s.jpg"), "--plot", str(tmp_path / "p.png")]) == 0
    eta, takeovers, _, off_road, reversed_s = _closed_loop(data, model, None, None)
    assert main(["data", "road", str(data)]) == 0
    assert calls == ["drive", "road", "drive", "road", "road"]
    record = json.loads(out.read_text())
    assert (record["eta"], record["interventions"], record["off_road_s"], record["reversing_s"]) == (
        eta, takeovers, off_road, reversed_s)


def test_only_the_chosen_rows_are_driven_each_stretch_from_the_recorded_path(tmp_path: Path) -> None:
    """Issue 43: a model is checked on the stretches its training held out, so drive-log drives chosen rows only."""
    from protocol.datalog import read_log
    from tools.drivelog.loop import LoopRules, drive
    from tools.drivelog.path import recorded_drive
    from tools.drivelog.rows import chosen_rows, parse_row_ranges, rows_mask

    samples = read_log(_curve_log(tmp_path, steering=0.0))[0]
    log = recorded_drive(samples)
    keep = rows_mask(samples, parse_row_ranges("3-10,20-30"))
    assert list(np.flatnonzero(keep)) == [*range(2, 10), *range(19, 30)]
    cut, _ = chosen_rows(log, None, keep)
    assert [p.name for p in cut.frames] == [log.frames[i].name for i in np.flatnonzero(keep)]
    assert len(np.unique(cut.session)) == 2 and cut.arc[0] == 0.0 and cut.arc[8] == 0.0 and cut.dt[7] == 0.0
    shown: list[str] = []
    result = drive(cut, lambda view, i: shown.append(cut.frames[i].name) or 0.0,
                   LoopRules(lane="path", speed_limit_kmh=0.0, wheelbase_m=2.6), snapshots=0)
    assert set(shown) == {p.name for p in cut.frames[:7]} | {p.name for p in cut.frames[8:-1]}  # not the ends
    assert result.driving_time_s == pytest.approx(float(cut.dt.sum()))  # the gap between the stretches not driven


def test_drive_log_drives_the_rows_asked_for_or_those_a_run_held_out(tmp_path: Path) -> None:
    from dataclasses import asdict

    from models.data.trainingdata import split_logs
    from models.training.train_config import TrainConfig
    from protocol.datalog import read_log
    from tools.drivelog.rows import held_out_mask

    data = _curve_log(tmp_path)
    out = tmp_path / "r.json"
    common = ["--data", str(data), "--baseline", "recorded", "--wheelbase", "2.6", "--lane", "path", "--json", str(out),
              "--strip", str(tmp_path / "s.jpg"), "--plot", str(tmp_path / "p.png")]
    assert main(["drive-log", *common, "--rows", "1-12,25-36"]) == 0
    record = json.loads(out.read_text())
    assert record["frames"] == 24 and record["rows"].endswith("24 frames in 2 stretches")
    # a training run's config.json says which logs it read and how it split them: the held-out blocks come back
    run = tmp_path / "run"
    run.mkdir()
    config = TrainConfig(data=[str(data)], out=str(run), block_frames=6, gap_frames=1, seed=3)
    (run / "config.json").write_text(json.dumps({"config": asdict(config)}))
    samples = read_log(data)[0]
    _, _, val = split_logs(config.data, config.seed, config.data_options())
    assert list(np.flatnonzero(held_out_mask(samples, run))) == list(val) and 0 < len(val) < len(samples)
    assert main(["drive-log", *common, "--held-out-of", str(run)]) == 0
    assert json.loads(out.read_text())["frames"] == len(val)
    # a run that read every 2nd row held out every 2nd row of its stretches: the stretches are driven whole
    strided = TrainConfig(data=[str(data)], out=str(run), block_frames=3, gap_frames=1, seed=3, row_stride=2)
    (run / "config.json").write_text(json.dumps({"config": asdict(strided)}))
    dataset, _, val = split_logs(strided.data, strided.seed, strided.data_options())
    mask = held_out_mask(samples, run)
    lines = [s.line for s in samples]
    for block in np.split(val, np.flatnonzero(np.diff(val) != 1) + 1):
        first, last = lines.index(dataset.samples[block[0]].line), lines.index(dataset.samples[block[-1]].line)
        assert mask[first:last + 1].all() and last - first == 2 * (len(block) - 1)
    assert mask.sum() == sum(2 * len(b) - 1 for b in np.split(val, np.flatnonzero(np.diff(val) != 1) + 1))
    assert main(["drive-log", *common, "--rows", "900-950"]) == 2


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("rbc drive-log: error") and "\n" not in err and "Traceback" not in err
    return err


def test_bad_rows_or_run_folders_are_one_line_with_a_hint(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 51: rows.py raised bare ValueErrors and the command turned every ValueError into a line without a hint;
    a run folder whose config.json held no object was a traceback."""
    common = ["drive-log", "--data", str(SAMPLE), "--baseline", "zero"]
    assert main([*common, "--rows", ","]) == 2
    assert "hint: give 1-based ranges FIRST-LAST" in _one_line(capsys)
    run = tmp_path / "run"
    run.mkdir()
    for stored in ("not json", json.dumps({"other": 1}), json.dumps({"config": [1, 2]})):
        (run / "config.json").write_text(stored)
        assert main([*common, "--held-out-of", str(run)]) == 2
        assert "not a training run's config" in _one_line(capsys)


def test_a_bug_under_drive_log_keeps_its_traceback(monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 51: the command caught every ValueError, so a bug inside the row choice read as bad input (exit 2)."""
    import tools.drivelog.rows as rows

    def broken(samples: object, ranges: object) -> np.ndarray:
        raise ValueError("operands could not be broadcast together")  # as numpy says it: a bug, not the user's

    monkeypatch.setattr(rows, "rows_mask", broken)
    with pytest.raises(ValueError, match="broadcast"):
        main(["drive-log", "--data", str(SAMPLE), "--baseline", "zero", "--rows", "1-5"])


def test_the_drive_log_library_refuses_bad_input_as_user_errors() -> None:
    from protocol.errors import UserError
    from tools.drivelog.drivers import make_driver
    from tools.drivelog.rows import parse_row_ranges

    with pytest.raises(UserError, match="no range"):
        parse_row_ranges(" , ")
    with pytest.raises(UserError, match="unknown baseline 'left'"):
        make_driver(None, None, "left")  # type: ignore[arg-type]


def test_the_closed_loop_flags_are_one_declaration_in_both_commands() -> None:
    """Issue 51: rbc drive-log and rbc data crossval declared --lane, --max-offset and --handback each on their own,
    with two wordings and two defaults for the hand-back (6 and None)."""
    import argparse

    from tools.cli import BY_NAME, load, subcommand_parser
    from tools.drivelog.loop import LoopRules

    def flags(parser: argparse.ArgumentParser) -> dict[str, tuple[object, ...]]:
        return {a.dest: (a.option_strings, a.default, a.choices, a.metavar, a.help, a.type)
                for a in parser._actions if a.dest in ("lane", "max_offset", "handback")}

    drive_log = subcommand_parser(BY_NAME["drive-log"], load(BY_NAME["drive-log"]))
    data = subcommand_parser(BY_NAME["data"], load(BY_NAME["data"]))
    crossval = next(a for a in data._actions if isinstance(a, argparse._SubParsersAction)).choices["crossval"]
    assert flags(drive_log) == flags(crossval) and len(flags(drive_log)) == 3
    assert crossval.parse_args(["--models", "m-{fold}.onnx"]).handback == LoopRules.handback_s


def test_a_model_with_a_monitor_says_which_take_overs_it_foresaw(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """drive-log scores the model's monitor on the views it drives from, as drive_server --monitor warn would."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from helpers_server import build_shallow
    from test_monitor import _brightness_graph, _with_monitor

    from drive_server.serving.monitor import MonitorSpec

    model = _with_monitor(build_shallow(tmp_path / "m.onnx", seed=3), tmp_path / "mon.onnx",
                          MonitorSpec("brightness", -0.5, 0.5, 3), _brightness_graph())
    out = tmp_path / "r.json"
    assert main(["drive-log", "--data", str(_curve_log(tmp_path)), "--model", str(model), "--wheelbase", "2.6",
                 "--json", str(out), "--strip", str(tmp_path / "s.jpg"), "--plot", str(tmp_path / "p.png")]) == 0
    record = json.loads(out.read_text())
    monitor = record["monitor"]
    assert monitor["frames_scored"] > 0 and monitor["episodes"] >= 1  # always above its warning threshold
    assert monitor["takeovers_scored"] <= record["interventions"]
    assert monitor["foreseen"] == sum(x is not None for x in monitor["leads_s"])
    assert "monitor: " in capsys.readouterr().out
