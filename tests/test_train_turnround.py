"""Training can leave out the rows where the driver turned the car round (#52): the log's speed has no sign, so a
reversing car's rows pair the picture with the opposite wheel. One rule finds them for training and for the
closed-loop measure."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from test_drive_log_reversing import _log, _turn_round  # the scripted logs live with the measure's tests

from models.data.behavior import pipeline_for
from models.data.split import SplitSpec
from models.data.trainingdata import DataOptions, prepare_data
from models.data.turnround import turnround_rows
from models.training.run_lines import describe_data
from models.training.train_config import TrainConfig
from protocol.datalog import read_log
from tools.drivelog.path import reversing


def test_training_and_the_measure_find_the_same_rows(tmp_path: Path) -> None:
    rows, backwards = _turn_round()
    drive = _log(tmp_path, rows)
    samples = read_log(tmp_path / "drive")[0]
    assert list(np.flatnonzero(turnround_rows(samples))) == list(backwards)
    assert (turnround_rows(samples) == reversing(drive)).all()


def test_drop_turnround_leaves_out_the_turn_and_says_so(tmp_path: Path) -> None:
    rows, backwards = _turn_round()
    _log(tmp_path, rows)
    data = tmp_path / "drive"
    pipeline = pipeline_for("simplistic", "shallow", "ours")
    kept_all = prepare_data([data], pipeline, 0, DataOptions(SplitSpec("random")), workers=1)
    options = DataOptions(SplitSpec("random"), drop_turnround=True)
    dropped = prepare_data([data], pipeline, 0, options, workers=1)
    assert kept_all.counts["kept"] == len(rows) and kept_all.counts["turnround"] == 0
    assert dropped.counts["turnround"] == len(backwards) and dropped.counts["slow"] == 0
    assert dropped.counts["kept"] == len(rows) - len(backwards)
    used = set(np.concatenate([dropped.train, dropped.val]).tolist())
    assert not used & set(backwards) and used == set(range(len(rows))) - set(backwards)
    assert f"{len(backwards)} of turns round dropped" in dropped.summary(options)
    config = TrainConfig(data=[str(data)], out=str(tmp_path / "run"), drop_turnround=True)
    assert config.data_options().drop_turnround
    assert any(f"leaving out {len(backwards)} of turns round" in line for line in describe_data(dropped, config))
