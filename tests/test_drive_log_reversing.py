"""The recorded driver's own manoeuvres (#52): where the driver reversed (turning round at a road's end, backing
away from a wall, a three-point turn) the person drives the recorded path, and that time is not counted; a
hairpin the driver follows forwards at full lock is driven by the model as any bend."""

from __future__ import annotations

import csv
import shutil
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from protocol.datalog import read_log
from tools.drivelog.loop import LoopRules, drive
from tools.drivelog.path import RecordedDrive, recorded_drive, reversing
from tools.drivelog.record import result_record

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
FRAMES = 36  # the sample's rows


def _log(tmp_path: Path, rows: list[tuple[float, float, float, float]]) -> RecordedDrive:
    """The sample's frames (and time stamps) with (steering, throttle, brake, speed in mph) per row (below the
    deploy speed limit: one step of the loop per frame)."""
    assert len(rows) == FRAMES
    out = tmp_path / "drive"
    shutil.copytree(SAMPLE, out)
    lines = list(csv.reader((out / "driving_log.csv").open(newline=""), skipinitialspace=True))
    with (out / "driving_log.csv").open("w", newline="") as fh:
        for line, row in zip(lines, rows, strict=True):
            csv.writer(fh).writerow([*line[:3], *row])
    return recorded_drive(read_log(out)[0])


def _hairpin() -> list[tuple[float, float, float, float]]:
    """Forwards: braking from 15 to 6 mph into the hairpin, round it at full lock on the throttle, and out."""
    slowing = [(0.0, 0.0, 0.6, 15.0 - 1.2 * k) for k in range(8)]
    round_it = [(1.0, 0.5, 0.0, 6.0 + 0.2 * k) for k in range(18)]
    out = [(0.0, 1.0, 0.0, 10.0 + 0.5 * k) for k in range(10)]
    return slowing + round_it + out


def _turn_round() -> tuple[list[tuple[float, float, float, float]], range]:
    """Forwards to a stop at a road's end, backing round at full lock (the brake key: faster backwards), rolling
    to a stop, forwards at the other full lock to complete the turn, then on along the road; and the rows where
    the driver was turning round."""
    to_stop = [(0.0, 0.0, 1.0, max(0.2, 14.0 - 3.0 * k)) for k in range(6)]  # 14 .. 0.2 mph at rows 0-5
    backing = [(1.0, 0.0, 1.0, 0.6 + 0.8 * k) for k in range(14)]  # 0.6 .. 11 mph backwards, rows 6-19
    rolling = [(0.0, 1.0, 0.0, 9.0 - 3.0 * k) for k in range(3)] + [(0.0, 1.0, 0.0, 0.3)]  # rows 20-23
    leg = [(-1.0, 1.0, 0.0, 1.5 + 1.0 * k) for k in range(4)]  # rows 24-27
    away = [(-0.3, 1.0, 0.0, 5.5 + 1.0 * k) for k in range(8)]  # rows 28-35
    return to_stop + backing + rolling + leg + away, range(5, 28)


def test_a_hairpin_driven_forwards_at_full_lock_is_no_manoeuvre(tmp_path: Path) -> None:
    log = _log(tmp_path, _hairpin())
    assert log.brake is not None and log.brake.max() > 0  # it braked into the hairpin: braking slows, not reverses
    assert not reversing(log).any()


def test_turning_round_backwards_is_the_drivers_own_manoeuvre_from_standstill_to_standstill(tmp_path: Path) -> None:
    rows, backwards = _turn_round()
    flags = reversing(_log(tmp_path, rows))
    assert list(np.flatnonzero(flags)) == list(backwards)


def test_a_speed_jitter_under_the_brake_is_not_reversing(tmp_path: Path) -> None:
    """Braking on a slope the speed may rise a little for a frame or two: not the car backing away."""
    rows = [(0.0, 0.0, 0.3, 10.0 + (0.1 if k % 3 == 1 else 0.0)) for k in range(FRAMES)]
    rows[10:14] = [(0.0, 0.0, 0.3, 10.0 + 0.05 * k) for k in range(4)]  # rising 0.15 mph over 3 frames
    assert not reversing(_log(tmp_path, rows)).any()


def _keeps_forwards(log: RecordedDrive, backwards: range):
    """A driver that steers as the recorded driver did while going forwards, and keeps straight on where the
    recorded driver reversed (a car that drives forwards cannot follow it)."""
    return lambda view, i: 0.0 if i in backwards else float(log.steering[i])


def test_where_the_driver_reversed_the_person_drives_and_it_is_not_counted(tmp_path: Path) -> None:
    rows, backwards = _turn_round()
    log = _log(tmp_path, rows)
    path_rule = LoopRules(lane="path", wheelbase_m=2.6)
    before = drive(log, _keeps_forwards(log, backwards), LoopRules(lane="path", wheelbase_m=2.6,
                                                                   person_reverses=False), snapshots=0)
    assert before.interventions >= 1 and before.reversing_s == 0  # taken over for not backing round
    after = drive(log, _keeps_forwards(log, backwards), path_rule, snapshots=0)
    assert after.interventions == 0
    moving = (log.speed >= 1.0) & (log.dt > 0)
    reversed_s = float(log.dt[moving & np.isin(np.arange(len(log)), list(backwards))].sum())
    assert after.reversing_s == pytest.approx(reversed_s) and after.reversing_s > 1.0
    assert after.driving_time_s + after.reversing_s == pytest.approx(float(log.dt[moving].sum()))  # on the path
    assert after.person is not None and after.person[list(backwards)[1:-1]].all()
    record = result_record(after, tmp_path, len(log), "forwards", 0.0)
    assert record["reversing_s"] == pytest.approx(reversed_s, abs=0.01)
    assert record["rules"] == asdict(path_rule) and record["rules"]["person_reverses"] is True


def test_a_hairpin_the_driver_follows_forwards_is_the_models_to_drive(tmp_path: Path) -> None:
    log = _log(tmp_path, _hairpin())
    result = drive(log, lambda view, i: 0.0, LoopRules(lane="path", wheelbase_m=2.6), snapshots=0)
    assert result.reversing_s == 0 and result.interventions >= 1  # not steering round it is a take-over
