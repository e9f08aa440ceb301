"""A training run's record (models.networks.runfiles.RunRecord): read as CSV and JSON, by everyone who reads a run.

What training writes is read back in tests/test_train.py (its run fixture); here the files a user or another
version may hand us."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from models.networks.runfiles import (
    CONFIG,
    HISTORY,
    MODEL,
    EpochRow,
    NotARunError,
    RunRecord,
    read_history,
    write_history,
    write_result,
)
from protocol.errors import BadValue

RECORD = {"config": {"arch": "shallow", "seed": 3, "data": ["/d/one"], "out": "/runs/x"},
          "resolved": {"epochs": 2, "steps_per_epoch": 5}, "rows": {"rows": 10}, "logs": [{"rows": 10}],
          "contract": {"width": 64}}
#: A history another tool touched: the header quoted, a column after the four, a quoted field holding a comma.
EDITED_HISTORY = ('"epoch","train_loss","val_loss","seconds","note"\n'
                  '1,0.25,0.125,60.5,"warm-up, slow"\n'
                  '2,0.0625,"0.03125",59.5,plain\n')


def _run(tmp_path: Path, history: str | None = EDITED_HISTORY, record: object = RECORD) -> Path:
    run = tmp_path / "run"
    run.mkdir(exist_ok=True)
    (run / CONFIG).write_text(json.dumps(record), encoding="utf-8")
    if history is not None:
        (run / HISTORY).write_text(history, encoding="utf-8")
    return run


def test_a_history_with_quoted_fields_and_an_extra_column_still_parses(tmp_path):
    """Was: DAgger split history.csv on commas, so a quoted field or a column more shifted every value."""
    run = _run(tmp_path)
    assert read_history(run / HISTORY) == [EpochRow(1, 0.25, 0.125, 60.5), EpochRow(2, 0.0625, 0.03125, 59.5)]
    record = RunRecord.load(run)
    assert record.last_epoch == EpochRow(2, 0.0625, 0.03125, 59.5) and isinstance(record.last_epoch.epoch, int)


def test_the_record_names_its_parts_and_files(tmp_path):
    run = _run(tmp_path, history=None)
    record = RunRecord.load(run)
    assert record.history == () and record.last_epoch is None
    assert record.config == RECORD["config"] and record.resolved == RECORD["resolved"]
    assert record.rows == {"rows": 10} and record.logs == [{"rows": 10}] and record.contract == {"width": 64}
    assert record.model_path == run / MODEL and record.result is None and record.recipe is None
    assert not record.finished
    record.config["seed"] = 99  # a copy: the record stays as read
    assert record.config["seed"] == 3


def test_the_result_is_added_to_the_record_and_a_run_is_finished_with_its_model(tmp_path):
    run = _run(tmp_path)
    write_result(run, {"exported_epoch": 2})
    (run / MODEL).write_bytes(b"onnx")
    record = RunRecord.load(run)
    assert record.result == {"exported_epoch": 2} and record.finished
    assert json.loads((run / CONFIG).read_text(encoding="utf-8")) == {**RECORD, "result": {"exported_epoch": 2}}


def test_history_round_trips_rows_as_training_keeps_them(tmp_path):
    rows = [{"epoch": 1, "train_loss": 0.1, "val_loss": 0.2, "seconds": 1.25}, EpochRow(2, 0.3, 0.4, 2.5)]
    write_history(tmp_path, rows)
    assert [r.as_dict() for r in read_history(tmp_path / HISTORY)] == [rows[0], {"epoch": 2, "train_loss": 0.3,
                                                                                 "val_loss": 0.4, "seconds": 2.5}]


@pytest.mark.parametrize(("record", "words"), [
    (None, "not a training run folder"),  # no record at all
    ("not json", "not a training run's config (not JSON"),
    ([1, 2], "not a training run's config (a JSON list)"),
    ({"other": 1}, "its config is no JSON object"),
    ({"config": [1]}, "its config is no JSON object"),
])
def test_a_folder_without_a_runs_record_is_a_users_error(tmp_path, record, words):
    run = tmp_path / "run"
    run.mkdir()
    if record is not None:
        (run / CONFIG).write_text(record if isinstance(record, str) else json.dumps(record), encoding="utf-8")
    with pytest.raises(NotARunError, match="not a training run") as exc:
        RunRecord.load(run)
    assert words in str(exc.value) and exc.value.hint


@pytest.mark.parametrize("history", ["epoch,train_loss,seconds\n1,0.1,2\n",  # a column missing
                                     "epoch,train_loss,val_loss,seconds\n1,x,0.1,2\n",  # not a number
                                     "epoch,train_loss,val_loss,seconds\n1,0.1\n"])  # a row cut short
def test_a_history_that_is_not_one_names_its_file(tmp_path, history):
    with pytest.raises(BadValue, match=HISTORY):
        RunRecord.load(_run(tmp_path, history))


def test_dagger_reads_a_rounds_training_through_the_record(tmp_path):
    """Was: tools/dagger/loop.py parsed history.csv with split(","): the quoted value was no number."""
    from tools.dagger.config import DaggerConfig
    from tools.dagger.loop import model_path, train_dir, train_round

    out = tmp_path / "dagger"
    run = train_dir(out, 0)
    run.mkdir(parents=True)
    (run / CONFIG).write_text(json.dumps({**RECORD, "config": {**RECORD["config"], "data": [str(out / "round-00" /
                                                                                              "data")]}}))
    (run / HISTORY).write_text(EDITED_HISTORY, encoding="utf-8")
    model_path(out, 0).write_bytes(b"onnx")  # trained: only read
    training = train_round(DaggerConfig(), out, 0)
    assert (training["val_loss"], training["train_loss"], training["epochs"]) == (0.03125, 0.0625, 2)
    assert training["config"]["data"] == ["round-00/data"] and training["resolved"] == RECORD["resolved"]
