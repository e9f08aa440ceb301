"""A DAgger run is keyed on its config, its recipe's content and the code of its steps; a round's evaluation
journal on its model and the code that drives: a resume never mixes two versions."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from protocol.errors import BadValue
from protocol.runrecords import read_json
from tests.scratch_code import STUBS, edit, write_tree
from tools.dagger import loop, scoring
from tools.dagger.config import DaggerConfig
from tools.evaluate import journal as eval_journal


def _config(recipe: Path) -> DaggerConfig:
    return DaggerConfig(budgets=(60, 120), episode_steps=60, epochs=1, eval_worlds=1, tracks=(), seed=3,
                        recipe=str(recipe))


def test_a_resume_under_another_recipe_or_code_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    code = write_tree(tmp_path / "code")
    monkeypatch.setattr(loop, "CODE_ROOT", code, raising=False)  # its code read from the scratch tree
    recipe = tmp_path / "r.toml"
    recipe.write_text("[training]\nepochs = 1\n", encoding="utf-8")
    config, out = _config(recipe), tmp_path / "run"
    loop.prepare_run(config, out, resume=False)
    loop.prepare_run(config, out, resume=True)
    edit(code, "docs/page.md", "not a step's code\n")
    loop.prepare_run(config, out, resume=True)
    for name in ("tools/dagger/loop.py", "models/training/metrics.py", "tools/console.py"):  # a step, training
        edit(code, name, STUBS[name] + "\nCHANGED = 1\n")
        with pytest.raises(BadValue, match="another code"):
            loop.prepare_run(config, out, resume=True)
        (out / loop.RUN_FILE).unlink()
        loop.prepare_run(config, out, resume=False)
    recipe.write_text("[training]\nepochs = 2\n", encoding="utf-8")
    with pytest.raises(BadValue, match="another recipe_sha256"):
        loop.prepare_run(config, out, resume=True)
    run = read_json(out / loop.RUN_FILE)
    run.pop("key")  # a run begun by the version before keys
    (out / loop.RUN_FILE).write_text(json.dumps(run), encoding="utf-8")
    with pytest.raises(BadValue, match="another recipe_sha256 and code"):
        loop.prepare_run(config, out, resume=True)


def test_a_rounds_evaluation_journal_holds_for_its_model_and_code_only(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    code = write_tree(tmp_path / "code")
    monkeypatch.setattr(eval_journal, "CODE_ROOT", code, raising=False)  # its code read from the scratch tree
    model, folder = tmp_path / "model.onnx", tmp_path / "eval"
    folder.mkdir()
    model.write_bytes(b"one")
    line = '{"experiment": "no_variation"}\n'

    def kept() -> bool:
        journal = scoring._journal_for(model, folder)
        was = journal.is_file()
        journal.write_text(line, encoding="utf-8")
        return was

    assert not kept() and kept()
    model.write_bytes(b"two")  # the round's model made again
    assert not kept() and (folder / "runs.previous.jsonl").read_text(encoding="utf-8") == line
    assert kept()
    edit(code, "tools/sim/driving/rules.py", STUBS["tools/sim/driving/rules.py"].replace("100", "95"))
    assert not kept() and kept()
