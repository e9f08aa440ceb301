"""An evaluation's record (tools.evaluate.evalrecord.EvalRecord): written by rbc eval, read by rbc compare.

What a real rbc eval writes is read back in tests/test_evaluate_e2e.py; here the files a user may hand us."""

from __future__ import annotations

import json

import pytest

from protocol.errors import BadValue
from tools.cli import main
from tools.evaluate.evalrecord import RESULTS, EvalRecord, NoEvaluationError

META = {"model": "m.onnx", "model_resolved": "/abs/m.onnx", "model_sha256": "ab" * 32, "behavior": "rigorous"}


def test_a_record_round_trips_and_names_its_parts(tmp_path):
    runs = [{"experiment": "no_variation", "seed": 0, "value": None}]
    written = EvalRecord(tmp_path, META, {"no_variation": {"measure": "eta"}}, runs).write()
    assert written == tmp_path / RESULTS
    record = EvalRecord.load(tmp_path)
    assert (record.meta, record.summary, list(record.runs)) == (META, {"no_variation": {"measure": "eta"}}, runs)
    assert (record.behavior, str(record.model), str(record.model_resolved)) == ("rigorous", "m.onnx", "/abs/m.onnx")
    assert record.model_sha256 == "ab" * 32


def test_an_older_record_without_the_absolute_path_falls_back_to_the_given_one(tmp_path):
    record = EvalRecord.from_dict({"meta": {"model": "m.onnx", "model_sha256": "x"}}, tmp_path)
    assert str(record.model_resolved) == "m.onnx" and record.summary == {} and list(record.runs) == []
    with pytest.raises(BadValue, match="its meta has no 'behavior'"):
        _ = record.behavior


@pytest.mark.parametrize("text", ["not json", "[1]", json.dumps({"summary": {}}), json.dumps({"meta": 1}),
                                  json.dumps({"meta": {}, "runs": {"a": 1}})])
def test_a_file_that_is_no_evaluation_is_a_users_error(tmp_path, text):
    (tmp_path / RESULTS).write_text(text, encoding="utf-8")
    with pytest.raises(BadValue, match=RESULTS):
        EvalRecord.load(tmp_path)


def test_compare_of_a_folder_without_an_evaluation_is_one_line_with_a_hint(tmp_path, capsys):
    with pytest.raises(NoEvaluationError):
        EvalRecord.load(tmp_path)
    assert main(["compare", "--eval", str(tmp_path), "--out", str(tmp_path / "t.md")]) == 2
    err = capsys.readouterr().err
    assert f"has no {RESULTS}" in err and "rbc eval --out" in err and "Traceback" not in err


def test_compare_of_a_results_file_that_is_no_evaluation_is_one_line(tmp_path, capsys):
    """Was: rbc compare read results["meta"]["behavior"]: a KeyError's traceback."""
    (tmp_path / RESULTS).write_text(json.dumps({"summary": {}}), encoding="utf-8")
    assert main(["compare", "--eval", str(tmp_path), "--layout", "table9", "--out", str(tmp_path / "t.md")]) == 2
    err = capsys.readouterr().err
    assert "not an evaluation's record" in err and "Traceback" not in err
