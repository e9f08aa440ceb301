"""Model cards: what a model is, how to use, measure and rebuild it, said from its training run; no result figures."""

from __future__ import annotations

import json
import re
from dataclasses import asdict
from pathlib import Path

import pytest

from models.networks.runfiles import RunRecord
from models.onnxfiles.model_card import CardSource, ModelFile, card
from models.training.recipe import load_recipe, recipe_sections
from models.training.train_config import TrainConfig
from tools.cli import main

REPO = Path(__file__).resolve().parents[1]
SECTIONS = ("## What it is", "## How to use it", "## How well it drives", "## Known limits", "## Reproduce")
#: What this generator wrote before: a table of figures (validation MSE, training time, a closed-loop lap).
OLD_CARD = """# `simplistic.onnx`: simplistic driving behavior

The paper's shallow CNN (14,065 parameters, 64x64 input) trained with the paper's approach on data recorded by
`rbc collect` in the headless simulator.

| | |
|---|---|
| training time | 2.0 min on a 2-core CPU |
| validation MSE | 0.01250 (final epoch, random split) |
| closed loop, no variation | eta = 100.0 % on `lake`, 0 interventions, lap 175 s at 20.6 km/h mean (limit 25) |

Reproduce (one command; deterministic per seed):

```bash
rbc train ...
```
"""
#: A result figure: a table row, a percentage, an error to four decimals, eta, a time or a speed.
FIGURE = re.compile(r"^\|.*\|$|\d %|\d%|\d\.\d{4,}|\beta\b|\d (min|km/h)\b", re.M)


def shape_problems(text: str, recipe: str) -> list[str]:
    """What keeps ``text`` from being a reference card: a missing section, a figure, its recipe not named."""
    problems = [f"no {s}" for s in SECTIONS if s not in text]
    problems += [f"a figure: {m.group(0)!r}" for m in FIGURE.finditer(text)]
    named = f"`{recipe}`" in text and any(f"--recipe {r} " in text for r in (recipe, Path(recipe).stem))
    return problems + ([] if named else ["the recipe unnamed"])


def _record(**kw) -> dict:
    """A run's config.json as rbc train writes it."""
    val = kw.pop("val_data", ["/data/real/A"])
    config = TrainConfig(data=["/data/gen"], out="runs/x", val_data=val, crop_top=64, crop_bottom=136,
                         decode_reduce=2, epochs=4, **kw)
    zero = {"zero_steer_train_samples": 500}
    return {"config": asdict(config), "recipe": recipe_sections(config), "contract": asdict(config.pipeline().contract),
            "resolved": {"epochs": 4, "steps_per_epoch": 7728, "deletion_rate": 0.7, "optimizer": "Adam", "loss": "MSE",
                         "train_samples": 900, "val_samples": 80, **zero,
                         "split": {"kind": config.split}},
            "rows": {"rows": 1100, "stride": 1}, "result": {"exported_epoch": 3},
            "logs": [{"path": f"{d}/driving_log.csv", "rows": n, "samples": n, "skipped": 0}
                     for d, n in zip(["/data/gen", *val], [1000, 100], strict=False)]}


def _card(record: dict, model: str = "models/pretrained/x.onnx", recipe_name: str = "", **info) -> str:
    c = record["config"]
    info = {"parameters": 14065, "camera_rig": "unity", "mirror_average": c["mirror_average"], **info}
    smooth = info.pop("smooth", c["smoothing"])
    home = {"rigorous": "--track mountain", "collision": "--track lake --cones 20 --cone-seed 1"}
    return card(CardSource(RunRecord.from_dict(record), ModelFile(Path(model), info, record["contract"], smooth),
                           Path(model).with_suffix(".toml"), home.get(c["behavior"], "--track lake"),
                           recipe_name=recipe_name))


@pytest.fixture(autouse=True)
def _in_repo(monkeypatch):
    monkeypatch.chdir(REPO)  # the cards' links are relative to where they lie


def test_a_card_has_the_reference_sections_and_no_result_figures():
    text = _card(_record())
    assert shape_problems(text, "models/pretrained/x.toml") == []
    assert text.startswith("# `x.onnx`: a simplistic driving model\n\n")
    assert shape_problems(OLD_CARD, "models/pretrained/x.toml")  # the old card fails: table, figures, no sections


def test_what_it_is_says_the_facts_of_the_run_and_the_file():
    text = " ".join(_card(_record(), mirror_average=True, smooth=0.5).split())
    assert "**Network**: the paper's shallow CNN, 14,065 parameters." in text
    assert "rows 64-136 resized to 64x64, RGB, scaled to -0.5..0.5; the JPEG is decoded at 1/2 size" in text
    assert "the `unity` [camera rig](../../docs/glossary.md#camera-rig)" in text
    assert "`/data/gen` (1,000 rows): 900 training samples (500 of them steering 0, before balancing)" in text
    assert "the recordings `/data/real/A` (100 rows): 80 samples, never trained on" in text
    assert "4 epochs of 7,728 steps of 256 samples (64 augmentation loops), Adam at learning rate 0.001" in text
    assert "seed 0" in text and "(epoch 3 of 4)" in text
    assert "(f(x) - f(mirrored x)) / 2. `drive_server` smooths its steering with 0.5." in text
    assert "`rbc mirror` made the file" in text and "drives the middle of the road" in text


def test_how_to_use_and_how_well_name_the_file_and_point_to_the_results():
    text = _card(_record())
    model = "models/pretrained/x.onnx"
    assert f"rbc sim --model {model} --track lake\ndrive_server --model {model}" in text
    assert "rbc eval --behavior simplistic --model models/pretrained/x.onnx --out eval/x" in text
    assert "rbc drive-log --data /data/real/A --model models/pretrained/x.onnx" in text
    assert "rbc score --data /data/real/A --model models/pretrained/x.onnx" in text
    assert "[Results](../../docs/results.md)" in text and "(../../docs/evaluate.md)" in text


def test_reproduce_names_the_recipe_the_train_command_and_how_the_file_was_made():
    text = _card(_record(), mirror_average=True, smooth=0.5)
    reproduce = text.split("## Reproduce")[1]
    assert "`models/pretrained/x.toml` beside this card" in reproduce
    assert ("rbc train --recipe models/pretrained/x.toml --data /data/gen --val-data /data/real/A --out runs/x"
            in reproduce)
    assert "rbc mirror runs/x/model.onnx --out models/pretrained/x.onnx --serve-smooth 0.5" in reproduce
    assert "rbc mirror" not in _card(_record(), model="runs/x/model.onnx")  # the run's own file: train only
    assert "rbc train --recipe x --data" in _card(_record(), recipe_name="x")  # bundled: by name, as the others


def test_other_networks_approaches_and_behaviors():
    text = " ".join(_card(_record(arch="pilotnet", approach="nvidia", behavior="rigorous", split="random",
                                  val_data=[]), parameters=252219).split())
    assert "NVIDIA's PilotNet, 252,219 parameters" in text and "NVIDIA's [approach]" in text
    assert "rows 64-136 resized to 200x66, YUV, scaled to 0..1" in text
    assert "--track mountain" in text and "held out at random" in text and "validation error is optimistic" in text
    assert "--data DIR" in text and "--val-data" not in text
    assert "--cones 20 --cone-seed 1" in _card(_record(behavior="collision"))


def _onnx_model(path: Path, info: dict, contract: dict) -> None:
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 64, 64, 3])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 64, 64, 3])
    model = helper.make_model(helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "m", [x], [y]),
                              opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    for key, value in (("rbc.model", info), ("rbc.preprocess", contract)):
        model.metadata_props.add(key=key, value=json.dumps(value))
    onnx.save(model, str(path))


def test_the_command_writes_the_card_and_the_runs_resolved_recipe_beside_it(tmp_path, capsys):
    run = tmp_path / "runs" / "x"
    run.mkdir(parents=True)
    record = _record()
    (run / "config.json").write_text(json.dumps(record))
    _onnx_model(run / "model.onnx", {"parameters": 14065, "camera_rig": "unity"}, record["contract"])
    assert main(["model-card", str(run)]) == 0
    text, recipe = (run / "model.md").read_text(), run / "model.toml"
    assert shape_problems(text, recipe.as_posix()) == []
    assert recipe_sections(load_recipe(str(recipe))) == record["recipe"]  # read back, it gives the same run
    recipe.write_text('# mine\n[data]\nsplit = "recordings"\n[network]\ncrop_top = 64\ncrop_bottom = 136\n'
                      "decode_reduce = 2\n[training]\nepochs = 4\n")
    assert main(["model-card", str(run)]) == 0 and recipe.read_text().startswith("# mine")  # the same run: kept
    recipe.write_text("[training]\nepochs = 5\n")
    assert main(["model-card", str(run)]) == 2 and "gives another run" in capsys.readouterr().err
    assert recipe.read_text() == "[training]\nepochs = 5\n"  # never overwritten
