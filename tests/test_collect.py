"""``rbc collect``: the Udacity log format read back, determinism, output-folder rules, Ctrl-C safety."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import pytest
from test_rules import stadium  # the small test tracks live with the rules tests

from tools.sim.collect.dataset import CollectConfig, OutputDirError, collect

NAME = re.compile(r"^(center|left|right)_\d{4}_\d{2}_\d{2}_\d{2}_\d{2}_\d{2}_\d{3}\.jpg$")


@pytest.fixture(scope="module")
def small_track(tmp_path_factory) -> str:
    return stadium(tmp_path_factory.mktemp("track"), straight=30.0, radius=16.0)  # ~160 m


def _config(track: str, **kw) -> CollectConfig:
    return CollectConfig(track=track, rate_hz=kw.pop("rate_hz", 4.0), **kw)


def _read(out: Path):
    try:
        from protocol.datalog import read_log
    except ImportError:  # the training package is optional here
        pytest.skip("protocol.datalog is not available")
    samples, report = read_log(out)
    assert not report.skipped, report.summary()
    return samples


def test_three_camera_log_reads_back_like_udacity_data(small_track, tmp_path):
    out = tmp_path / "run"
    result = collect(_config(small_track, cameras=3), out)
    assert result.rows > 50 and result.interventions == 0 and not result.interrupted
    lines = (out / "driving_log.csv").read_text().splitlines()
    assert len(lines) == result.rows
    first = lines[0].split(", ")
    assert len(first) == 7 and Path(first[0]).is_absolute()  # Udacity: ", " separators, absolute paths
    samples = _read(out)
    assert len(samples) == result.rows
    for s in samples:
        assert NAME.match(s.center.name) and NAME.match(s.left.name) and NAME.match(s.right.name)
        assert s.center.name[7:] == s.left.name[5:] == s.right.name[6:]  # one timestamp per row
        assert -1.0 <= s.steering <= 1.0 and 0 <= s.throttle <= 1 and 0 <= s.brake <= 1
    stamps = [s.center.name for s in samples]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    cruise = [s.speed for s in samples[len(samples) // 3:]]
    assert 14.0 < sum(cruise) / len(cruise) < 19.5  # mph by default: 30 km/h = 18.6 mph, slower in bends
    zero = sum(s.steering == 0.0 for s in samples) / len(samples)
    assert zero == pytest.approx(result.zero_steer_share) and 0.2 < zero < 0.9  # the keyboard's zero imbalance
    img = cv2.imread(str(samples[10].center))
    assert img.shape == (160, 320, 3)


def test_one_camera_leaves_left_and_right_empty_and_speed_in_kmh(small_track, tmp_path):
    out = tmp_path / "one"
    collect(_config(small_track, cameras=1, speed_unit="kmh", rate_hz=2.0), out)
    assert not list((out / "IMG").glob("left_*")) and not list((out / "IMG").glob("right_*"))
    line = (out / "driving_log.csv").read_text().splitlines()[5]
    assert line.split(", ")[1:3] == ["", ""]
    samples = _read(out)
    assert all(s.left is None and s.right is None for s in samples)
    assert max(s.speed for s in samples) > 25.0  # km/h now


def test_same_seed_same_data(small_track, tmp_path):
    a = collect(_config(small_track, seed=4, cameras=1, rate_hz=2.0), tmp_path / "a")
    b = collect(_config(small_track, seed=4, cameras=1, rate_hz=2.0), tmp_path / "b")
    la = (tmp_path / "a" / "driving_log.csv").read_text().replace(str(tmp_path / "a"), "")
    lb = (tmp_path / "b" / "driving_log.csv").read_text().replace(str(tmp_path / "b"), "")
    assert a.rows == b.rows and la == lb
    name = sorted((tmp_path / "a" / "IMG").iterdir())[7].name
    assert (tmp_path / "a" / "IMG" / name).read_bytes() == (tmp_path / "b" / "IMG" / name).read_bytes()


def test_both_directions_doubles_the_laps(small_track, tmp_path):
    result = collect(_config(small_track, both_directions=True, cameras=1, rate_hz=1.0), tmp_path / "both")
    assert len(result.laps) == 2 and all(lap.completed for lap in result.laps) and result.interventions == 0


def test_refuses_a_non_empty_folder_unless_told(small_track, tmp_path):
    out = tmp_path / "busy"
    first = collect(_config(small_track, cameras=1, rate_hz=1.0), out)
    with pytest.raises(OutputDirError, match="--overwrite"):
        collect(_config(small_track, cameras=1, rate_hz=1.0), out)
    appended = collect(_config(small_track, cameras=1, rate_hz=1.0, seed=1), out, append=True)
    lines = (out / "driving_log.csv").read_text().splitlines()
    assert len(lines) == first.rows + appended.rows
    names = [ln.split(", ")[0].rsplit("/", 1)[-1] for ln in lines]
    assert names == sorted(names) and len(set(names)) == len(names)  # appended rows come later in time
    again = collect(_config(small_track, cameras=1, rate_hz=1.0), out, overwrite=True)
    assert len((out / "driving_log.csv").read_text().splitlines()) == again.rows
    assert len(list((out / "IMG").iterdir())) == again.rows


def test_ctrl_c_leaves_only_complete_rows(small_track, tmp_path):
    out = tmp_path / "cut"
    calls = 0

    def interrupt(done: float, total: float) -> None:
        nonlocal calls
        calls += 1
        if calls == 6:
            raise KeyboardInterrupt

    result = collect(_config(small_track, cameras=3, rate_hz=3.0), out, progress=interrupt)
    assert result.interrupted and result.rows > 0
    lines = (out / "driving_log.csv").read_text().splitlines()
    assert len(lines) == result.rows
    assert len(_read(out)) == result.rows  # every row parses and has its three images
    assert len(list((out / "IMG").iterdir())) == 3 * result.rows  # and no image without a row


def test_the_dynamic_car_collects_without_intervention(small_track, tmp_path):
    result = collect(_config(small_track, both_directions=True, cameras=1, rate_hz=1.0, vehicle="dynamic"),
                     tmp_path / "dyn")
    assert len(result.laps) == 2 and all(lap.completed for lap in result.laps) and result.interventions == 0
    assert 20.0 < result.laps[0].mean_speed_kmh < 31.0
