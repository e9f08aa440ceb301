"""An interrupted evaluation resumes from its journal: finished runs are reused, never run twice."""

import json
import subprocess
import sys
from concurrent.futures import Future
from pathlib import Path

import pytest

from tests.conftest import write_stadium
from tools.evaluate.runner import DriverSpec, Runner, Task, read_journal, record_key, task_key


def _eval(model, track, out, *extra):
    return subprocess.run(
        [sys.executable, "-m", "tools.cli", "eval", "--model", str(model), "--track", track,
         "--experiments", "no_variation", "position", "--seeds", "2", "--workers", "2", "--out", str(out), *extra],
        capture_output=True, text=True, timeout=240)


def test_read_journal_skips_a_line_cut_short(tmp_path):
    journal = tmp_path / "runs.jsonl"
    good = {"experiment": "no_variation", "value": None, "seed": 0, "scenario": {"track": "t", "seed": 0}}
    journal.write_text(json.dumps(good) + "\n" + json.dumps(good | {"seed": 1})[:25], encoding="utf-8")
    found = read_journal(journal)
    assert list(found) == [record_key(good)]


def test_runner_reuses_a_journaled_run_without_running_it(tmp_path):
    scenario = {"track": "nowhere", "seed": 3}
    done = {"experiment": "position", "value": 0.5, "seed": 3, "scenario": scenario, "autonomous": True}
    seen = []
    runner = Runner(DriverSpec(model="unused.onnx"), 1, tmp_path / "runs.jsonl", on_result=seen.append,
                    reuse={task_key("position", 0.5, 3, scenario): done})
    try:
        future = runner.submit(Task("position", "simplistic", 0.5, 3, scenario))
        assert isinstance(future, Future) and future.result(timeout=1) is done
    finally:
        runner.close()
    assert runner.records == [done] and runner.reused == 1 and seen == [done]
    assert not (tmp_path / "runs.jsonl").exists()  # reused runs are already in the journal


def test_resume_reuses_finished_runs_and_refuses_another_model(tmp_path, shallow_onnx):
    track = write_stadium(tmp_path, straight=40.0, radius=20.0)
    out = tmp_path / "eval"
    first = _eval(shallow_onnx, track, out)
    assert first.returncode == 0, first.stderr[-3000:]
    journal = out / "runs.jsonl"
    lines = journal.read_text().splitlines()
    assert len(lines) == 4  # 2 experiments x 2 seeds
    # simulate an interruption mid-write: the last record is cut in half
    journal.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2])

    second = _eval(shallow_onnx, track, out, "--resume")
    assert second.returncode == 0, second.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    assert results["meta"]["resumed_runs"] == 3 and results["meta"]["runs"] == 4
    rerun = [json.loads(line) for line in journal.read_text().splitlines()]
    assert len(rerun) == 4 and len({record_key(r) for r in rerun}) == 4
    assert "3 reused from the journal" in second.stdout

    doc = json.loads(Path(track).read_text(encoding="utf-8"))
    Path(track).write_text(json.dumps(doc | {"road_width": 9.0}), encoding="utf-8")  # the same file, another road
    edited = _eval(shallow_onnx, track, out, "--resume")
    assert edited.returncode != 0 and "different track_sha256" in edited.stderr

    from tools.bench.onnx_builders import save_model

    other = save_model("shallow", tmp_path / "other.onnx", seed=1)  # another model: another hash
    refused = _eval(other, track, out, "--resume")
    assert refused.returncode != 0 and "different model_sha256" in refused.stderr


def test_a_resume_after_a_change_to_the_code_that_drives_a_run_is_refused(tmp_path, monkeypatch):
    from tests.scratch_code import STUBS, edit, write_tree
    from tools.errors import CommandError
    from tools.evaluate import journal as eval_journal

    code = write_tree(tmp_path / "code")
    monkeypatch.setattr(eval_journal, "CODE_ROOT", code, raising=False)  # its code read from the scratch tree
    out, runs = tmp_path / "eval", tmp_path / "eval" / "runs.jsonl"
    out.mkdir()
    identity = {"model_sha256": "m", "behavior": "simplistic"}
    record = {"experiment": "no_variation", "value": None, "seed": 0, "scenario": {"track": "t", "seed": 0}}
    assert eval_journal.prepare_journal(out, runs, identity, resume=False) == {}
    runs.write_text(json.dumps(record) + "\n", encoding="utf-8")
    assert list(eval_journal.prepare_journal(out, runs, identity, resume=True)) == [record_key(record)]
    edit(code, "docs/page.md", "not the code that drives\n")
    assert list(eval_journal.prepare_journal(out, runs, identity, resume=True)) == [record_key(record)]
    for name in ("tools/sim/driving/rules.py", "tools/sim/track/builtin/lake.json", "tools/evaluate/runner.py"):
        edit(code, name, STUBS[name].replace("0", "1"))  # a number in eta's rule, in a track, in the runner
        with pytest.raises(CommandError, match="different code"):
            eval_journal.prepare_journal(out, runs, identity, resume=True)
        assert eval_journal.prepare_journal(out, runs, identity, resume=False) == {}  # a fresh start takes it
        runs.write_text(json.dumps(record) + "\n", encoding="utf-8")


def test_a_fresh_start_keeps_the_earlier_journal(tmp_path, shallow_onnx):
    out = tmp_path / "eval"
    out.mkdir()
    (out / "runs.jsonl").write_text('{"experiment": "x"}\n')
    track = write_stadium(tmp_path, straight=40.0, radius=20.0)
    proc = _eval(shallow_onnx, track, out, "--experiments", "no_variation", "--seeds", "1")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (out / "runs.previous.jsonl").read_text() == '{"experiment": "x"}\n'


@pytest.mark.parametrize("value", [None, 0.5, 10, -35.0, True])
def test_task_keys_survive_a_json_round_trip(value):
    record = {"experiment": "e", "value": value, "seed": 2, "scenario": {"a": 1.25, "b": None, "c": "lake"}}
    assert record_key(json.loads(json.dumps(record))) == task_key("e", value, 2, record["scenario"])
