"""rbc data crossval: each recording scored by its fold's model, open and closed loop, as one table."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tools.realdata.crossval import RecordingScore, model_for, score_recording, summarise
from tools.realdata.crossval_tables import format_tables
from tools.realdata.recordings import PublicRecording

DATA = Path(__file__).parent / "data"
MODEL = Path(__file__).parents[1] / "models" / "pretrained" / "unity.onnx"


def _rec(name: str = "udacity-sample", track: str = "lake", fold: str = "B") -> PublicRecording:
    return PublicRecording(name=name, track=track, repository="a/b", commit="0" * 40, folder="", rows=None,
                           input="keyboard", fold=fold)


def test_the_model_is_the_one_of_the_recordings_fold() -> None:
    assert model_for("runs/cv-{fold}/model.onnx", _rec(fold="C")) == Path("runs/cv-C/model.onnx")
    assert model_for("one.onnx", _rec(fold="C")) == Path("one.onnx")


def test_a_lake_recording_is_scored_open_and_closed_loop() -> None:
    s = score_recording(_rec(), DATA, MODEL)
    assert s.frames == 36 and s.zero_mse > 0 and -1 <= s.pearson_r <= 1
    assert -1 <= s.r_to_intent <= 1 and s.r_to_intent != s.pearson_r and 0 < s.intent_r < 1
    assert s.eta is not None and 0 <= s.eta <= 100 and s.interventions >= 0 and s.seconds_per_takeover > 0
    assert s.off_road_s is not None and s.off_road_s >= 0 and "off_road_s" in s.as_dict()  # as drive-log's JSON
    assert s.reversing_s == 0 and "reversing_s" in s.as_dict()  # the sample's driver never reverses
    # issue 43: the jungle and the mountain are driven too, their road found by the manifest's track's profile
    jungle = score_recording(_rec(track="jungle"), DATA, MODEL)
    assert jungle.eta is not None and jungle.off_road_s is not None and jungle.mse == s.mse
    open_loop = score_recording(_rec(track="mountain"), DATA, MODEL, closed_loop=False)
    assert open_loop.eta is None and open_loop.off_road_s is None and open_loop.mse == s.mse


def test_tables_summarise_by_track_and_mark_what_beats_always_0() -> None:
    scores = [RecordingScore("a", "lake", "A", "m", 10, 0.05, 0.04, 0.5, 20.0, 3, 8.0, 0.6, 0.8),
              RecordingScore("b", "lake", "B", "m", 10, 0.02, 0.03, 0.3, 40.0, 1, 12.0, 0.4, 0.6),
              RecordingScore("c", "jungle", "A", "m", 10, 0.2, 0.1, 0.6)]
    lake, jungle = summarise(scores)
    assert (lake.recordings, lake.mean_r, lake.beats_zero, lake.mean_eta) == (2, 0.4, 1, 30.0)
    assert (lake.mean_r_to_intent, lake.mean_intent_r) == (0.5, 0.7)
    # issue 43's targets are per recording: the worst, how many reach 95 %, and the take-overs beside the peer's
    assert (lake.worst_eta, lake.at_least_95, lake.takeovers) == (20.0, 0, 4)
    assert (jungle.worst_eta, jungle.at_least_95, jungle.takeovers) == (None, None, None)
    assert jungle.mean_eta is None and jungle.beats_zero == 1 and jungle.mean_intent_r is None
    # the closed loop's figures arrive as numpy numbers: the summary's counts are still JSON numbers, not the
    # strings json.dumps(default=str) made of numpy integers ("at_least_95": "22")
    numpy_scores = [replace(s, eta=np.float64(s.eta)) if s.eta is not None else s for s in scores]
    summary = json.loads(json.dumps([t.__dict__ for t in summarise(numpy_scores)], default=str))
    assert summary[0]["at_least_95"] == 0 and summary[0]["takeovers"] == 4 and summary[0]["worst_eta"] == 20.0
    text = format_tables(scores, peer=scores[:1])
    # seconds per take-over pooled over the track: (3 x 8 s + 1 x 12 s) / 4 take-overs, not the mean of 8 and 12
    assert "| lake | 2 | 0.70 | 0.40 | 0.50 | 1 of 2 | 30.0 | 9.0 | 0.50 | 0.60 | 1 of 1 | 20.0 | 8.0 |" in text
    assert "| a | lake | A | 10 | 0.0500 | **0.0400** | 0.50 | 0.80 | 0.60 | 20.0 (3; 8.0 s) | **0.0400** |" in text
    assert "| b | lake | B | 10 | 0.0200 | 0.0300 |" in text  # not bold: always-0 is better
    assert text.splitlines()[0].startswith("| track | recordings | r9 | mean r | r to intent |")  # the glossary's
    clean = format_tables([replace(scores[0], eta=100.0, interventions=0, seconds_per_takeover=60.0)])
    assert "| 100.0 (0) |" in clean and "60.0 s" not in clean  # no rate for no take-over
    assert "| 100.0 | – |" in clean  # ... in the track's row either
    # a recording without a take-over adds its driving time, not a made-up rate: (24 s + 1000 s) / 3
    (pooled,) = summarise([scores[0], replace(scores[1], eta=100.0, interventions=0, seconds_per_takeover=1000.0)])
    assert pooled.seconds_per_takeover == round(1024 / 3, 2)
    assert "| jungle | 1 | – | 0.60 | – | 1 of 1 | – | – | – | – | – | – | – |" in text


def test_the_command_names_a_missing_fold_model_in_one_line(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "tools.cli", "data", "crossval", "--root", str(tmp_path),
                          "--models", str(tmp_path / "cv-{fold}.onnx"), "--name", "0xR4Y"],
                         capture_output=True, text=True)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert f"no model at {tmp_path / 'cv-A.onnx'}" in out.stderr


@pytest.mark.parametrize("flag", [["--workers", "0"], ["--max-offset", "0"]])
def test_bad_settings_are_refused(tmp_path: Path, flag: list[str]) -> None:
    out = subprocess.run([sys.executable, "-m", "tools.cli", "data", "crossval", "--models", str(MODEL),
                          "--name", "0xR4Y", *flag], capture_output=True, text=True)
    assert out.returncode == 2 and "must be" in out.stderr and "Traceback" not in out.stderr
    assert not json.dumps(out.stdout).count("|")


# --------------------------------------------------------------------------- a cross-validation that survives a stop


def _two_recordings(tmp_path: Path) -> tuple[Path, list[PublicRecording]]:
    import shutil

    root = tmp_path / "real"
    root.mkdir()
    for name in ("one", "two"):
        shutil.copytree(DATA / "udacity-sample", root / name)
    return root, [_rec("one", fold="A"), _rec("two", fold="B")]


def test_a_resumed_crossval_takes_finished_recordings_from_its_journal_and_equals_the_clean_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from tools.realdata import crossval

    root, recs = _two_recordings(tmp_path)
    path = tmp_path / "cv.journal.jsonl"
    clean = crossval.score_all(recs, root, str(MODEL), journal=crossval.ScoreJournal(path))
    lines = path.read_text(encoding="utf-8").splitlines()
    assert len(lines) == 2
    path.write_text(lines[0] + "\n" + lines[1][: len(lines[1]) // 2], encoding="utf-8")  # killed mid-line
    scored = []
    real = crossval.score_recording
    monkeypatch.setattr(crossval, "score_recording", lambda rec, *a: scored.append(rec.name) or real(rec, *a))
    resumed = crossval.score_all(recs, root, str(MODEL), journal=crossval.ScoreJournal(path))
    assert scored == ["two"]  # the finished one is never redone; the torn one is
    assert resumed == clean
    assert crossval.ScoreJournal(path).get(next(iter(crossval.ScoreJournal(path).scores))) is not None
    assert len(crossval.ScoreJournal(path).scores) == 2  # the torn fragment did not swallow the new line


def test_a_retrained_model_at_the_same_path_is_scored_again(tmp_path: Path) -> None:
    from tools.realdata import crossval

    root, recs = _two_recordings(tmp_path)
    model = tmp_path / "m.onnx"
    model.write_bytes(MODEL.read_bytes())
    key = crossval.score_key("folds", "one", model, True, None, None)
    assert key == crossval.score_key("folds", "one", model, True, None, None)
    model.write_bytes(MODEL.read_bytes() + b"\0")
    assert key != crossval.score_key("folds", "one", model, True, None, None)
    assert key != crossval.score_key("folds", "one", MODEL, False, None, None)
    same = crossval.score_key("folds", "one", MODEL, True, None, None, code="git abc")
    assert same != crossval.score_key("folds", "one", MODEL, True, None, None, code="git abd")  # the measure changed
    assert same != crossval.score_key("folds", "one", MODEL, True, None, None, code="git abc", data="d")  # re-cut


def test_the_journal_key_covers_the_code_the_scorer_imports_and_nothing_else(tmp_path: Path) -> None:
    """The offline scorer, the labels, the metrics and eta's rules are the scorer's code as much as the closed loop:
    a change to any of them voids a journal; a change to the docs or to training code the scorer never runs does
    not."""
    from tests.scratch_code import STUBS, edit, write_tree
    from tools.realdata import crossval

    root = write_tree(tmp_path)
    version = crossval.measure_version(root)
    for name in ("models/training/train.py", "tools/console.py", "docs/page.md"):
        edit(root, name, "CHANGED = 1\n")
        assert crossval.measure_version(root) == version, name
    for name in ("tools/evaluate/offline.py", "models/data/labels.py", "models/training/metrics.py",
                 "tools/sim/driving/rules.py", "drive_server/serving/pipeline.py",
                 "tools/realdata/public_recordings.csv"):
        edit(root, name, STUBS[name] + "\nCHANGED = 1\n")
        assert crossval.measure_version(root) != version, name
        version = crossval.measure_version(root)
    assert crossval.measure_version() == crossval.measure_version()  # the checkout's own, stable


def test_a_resumed_crossval_scores_again_what_a_change_of_code_data_or_settings_touched(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from tests.scratch_code import STUBS, edit, write_tree
    from tools.realdata import crossval

    code = write_tree(tmp_path / "code")
    monkeypatch.setattr(crossval, "CODE_ROOT", code, raising=False)  # its code read from the scratch tree
    root, recs = _two_recordings(tmp_path)
    scored: list[str] = []

    def fake(rec, root, model, closed_loop, rules, smooth):
        scored.append(rec.name)
        return RecordingScore(rec.name, rec.track, rec.fold, str(model), 1, 0.1, 0.05, 0.5)

    monkeypatch.setattr(crossval, "score_recording", fake)
    path = tmp_path / "cv.journal.jsonl"

    def again(**settings) -> list[str]:
        scored.clear()
        crossval.score_all(recs, root, str(MODEL), journal=crossval.ScoreJournal(path), **settings)
        return sorted(scored)

    assert again() == ["one", "two"]
    assert again() == []  # all in the journal
    edit(code, "models/training/metrics.py", STUBS["models/training/metrics.py"] + "\nCHANGED = 1\n")
    assert again() == ["one", "two"]  # the scorer's code changed
    log = root / "one" / "driving_log.csv"
    log.write_text(log.read_text(encoding="utf-8").replace("0.", "1.", 1), encoding="utf-8")
    assert again() == ["one"]  # one recording's data changed
    assert again(smooth=0.5) == ["one", "two"]
    assert again(closed_loop=False) == ["one", "two"]
    assert again() == []


def test_journal_lines_that_no_longer_load_are_counted_in_one_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from tools.realdata import crossval

    score = RecordingScore("one", "lake", "A", "m", 1, 0.1, 0.05, 0.5)
    key = crossval.score_key("folds", "one", MODEL, True, None, None, "code 1", "data 1")
    old_key = json.dumps({k: v for k, v in json.loads(key).items() if k != "data"})  # before data was in the key
    whole = json.dumps({"key": key, "score": score.as_dict()})
    path = tmp_path / "cv.journal.jsonl"
    path.write_text("\n".join([whole, "not json", json.dumps({"key": old_key, "score": score.as_dict()}),
                               json.dumps({"key": key}), whole[:20]]), encoding="utf-8")
    with caplog.at_level("WARNING", logger="tools.realdata.crossval"):
        journal = crossval.ScoreJournal(path)
    assert journal.get(key) == score and len(journal.scores) == 1
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1 and str(path) in warnings[0] and " 4 line" in warnings[0]
    caplog.clear()
    with caplog.at_level("WARNING", logger="tools.realdata.crossval"):
        path.write_text(whole + "\n", encoding="utf-8")
        crossval.ScoreJournal(path)
    assert not caplog.records  # a sound journal says nothing


def test_the_command_writes_its_figures_and_resumes_to_the_same_json(tmp_path: Path) -> None:
    root = tmp_path / "real"
    root.mkdir()
    for name in ("0xR4Y", "2002Esala"):  # folds A and B of the manifest
        (root / name).symlink_to(DATA / "udacity-sample")
    out = tmp_path / "cv.json"
    cmd = [sys.executable, "-m", "tools.cli", "data", "crossval", "--root", str(root), "--models", str(MODEL),
           "--name", "0xR4Y", "--name", "2002Esala", "--workers", "1", "--json", str(out)]
    first = subprocess.run(cmd, capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    clean = json.loads(out.read_text(encoding="utf-8"))
    assert clean["folds_done"] == ["A", "B"] and len(clean["folds"]) == 2
    journal = tmp_path / "cv.journal.jsonl"
    journal.write_text(journal.read_text(encoding="utf-8").splitlines()[0] + "\n", encoding="utf-8")  # B unfinished
    out.unlink()
    again = subprocess.run(cmd + ["--plot", str(tmp_path / "cv.png")], capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert json.loads(out.read_text(encoding="utf-8")) == clean
    assert again.stdout.split("json")[0] == first.stdout.split("json")[0]  # the same tables
    assert (tmp_path / "cv.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "plot" in again.stdout


def test_the_picture_shows_every_driven_recording_by_track(tmp_path: Path) -> None:
    from tools.realdata.crossval_plot import plot_crossval

    rec = {"fold": "A", "model": "m", "frames": 10, "zero_mse": 0.1, "mse": 0.05, "pearson_r": 0.5}
    doc = {"folds": {"recordings": [{**rec, "name": "a", "track": "lake", "eta": 99.0},
                                    {**rec, "name": "b", "track": "jungle", "eta": 91.0},
                                    {**rec, "name": "c", "track": "mountain", "eta": None}]},
           "peer": {"recordings": [{**rec, "name": "a", "track": "lake", "eta": 80.0}]}}
    path = plot_crossval(doc, tmp_path / "cv.png")
    assert path.read_bytes()[:4] == b"\x89PNG" and list(tmp_path.iterdir()) == [path]  # no temporary file left
    with pytest.raises(ValueError, match="closed loop"):
        plot_crossval({"folds": {"recordings": [doc["folds"]["recordings"][2]]}}, tmp_path / "none.png")


def test_a_plot_into_a_missing_folder_is_refused_before_any_work(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "tools.cli", "data", "crossval", "--models", str(MODEL),
                          "--name", "0xR4Y", "--plot", str(tmp_path / "no" / "cv.png")], capture_output=True, text=True)
    assert out.returncode == 2 and "no folder" in out.stderr and "Traceback" not in out.stderr


def test_a_finished_fold_is_never_trained_again_and_an_interrupted_one_continues(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import models.training.train as train_module
    from tools.realdata import foldtrain

    root, recs = _two_recordings(tmp_path)
    recipe = tmp_path / "tiny.toml"
    recipe.write_text("[training]\nepochs = 1\nmax_steps_per_epoch = 2\n[augmentation]\naug_loops = 1\n",
                      encoding="utf-8")
    runs = tmp_path / "runs"
    model = foldtrain.train_fold(str(recipe), "B", recs, root, runs, progress=False)
    assert model == runs / "fold-B" / "model.onnx" and foldtrain.is_finished(runs / "fold-B")
    config = json.loads((runs / "fold-B" / "config.json").read_text(encoding="utf-8"))
    assert config["config"]["val_data"] == [str(root / "two")] and config["config"]["data"] == [str(root / "one")]

    calls = []

    def fake_train(cfg, resume=False):
        calls.append(resume)
        Path(cfg.out).mkdir(parents=True, exist_ok=True)
        (Path(cfg.out) / "config.json").write_text("{}", encoding="utf-8")  # what a run a stop interrupted leaves
        return type("R", (), {"interrupted": True, "onnx": None})()

    monkeypatch.setattr(train_module, "train", fake_train)
    assert foldtrain.train_fold(str(recipe), "B", recs, root, runs) == model  # finished: not trained
    assert calls == []
    assert foldtrain.train_fold(str(recipe), "A", recs, root, runs) is None  # stopped
    assert foldtrain.train_fold(str(recipe), "A", recs, root, runs) is None
    assert calls == [False, True]  # continued from its checkpoint, not started afresh


def test_a_fold_model_is_trained_again_when_its_recipe_data_or_code_changed(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    import models.training.train as train_module
    from tests.scratch_code import STUBS, edit, write_tree
    from tools.realdata import foldtrain

    code = write_tree(tmp_path / "code")
    monkeypatch.setattr(foldtrain, "CODE_ROOT", code, raising=False)  # its code read from the scratch tree
    root, recs = _two_recordings(tmp_path)
    recipe = tmp_path / "tiny.toml"
    recipe.write_text("[training]\nepochs = 1\n", encoding="utf-8")
    runs = tmp_path / "runs"
    trained: list[list[str]] = []

    def fake_train(cfg, resume=False):  # a finished run, at once
        trained.append(cfg.data)
        out = Path(cfg.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "model.onnx").write_bytes(b"onnx")
        (out / "config.json").write_text('{"config": {}, "result": {}}', encoding="utf-8")
        return type("R", (), {"interrupted": False, "onnx": out / "model.onnx"})()

    monkeypatch.setattr(train_module, "train", fake_train)

    def trains() -> bool:
        trained.clear()
        foldtrain.train_fold(str(recipe), "B", recs, root, runs, progress=False)
        return bool(trained)

    assert trains() and not trains()
    recipe.write_text("[training]\nepochs = 2\n", encoding="utf-8")
    with caplog.at_level("WARNING", logger="tools.realdata.foldtrain"):
        assert trains() and not trains()
    assert (runs / "fold-B.stale" / "model.onnx").is_file() and "other settings" in caplog.text
    log = root / "one" / "driving_log.csv"  # fold B's training data
    log.write_text(log.read_text(encoding="utf-8").replace("0.", "1.", 1), encoding="utf-8")
    assert trains() and not trains()
    edit(code, "models/training/metrics.py", STUBS["models/training/metrics.py"] + "\nCHANGED = 1\n")
    assert trains() and not trains()
    edit(code, "docs/page.md", "not the training's code\n")
    assert not trains()
    (runs / "fold-B" / "fold.json").unlink()  # a run of the version before keys
    assert trains() and not trains()
    trained.clear()
    foldtrain.train_fold(str(recipe), "B", recs, root, runs, progress=True)
    assert trained == []  # a progress bar changes no model
