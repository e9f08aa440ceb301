"""Training recipes (issue #45): ``rbc train --recipe FILE_OR_NAME``, the bundled recipes, and what moved there.

The settings that shape a model live in TOML files by section; the command line keeps where the data is and
how the machine runs. Every bundled model ships the recipe it was trained with, checked here against what its
ONNX file records and against its card's old command line read by the old flags' meaning.
"""

from __future__ import annotations

import json
import shlex
import tomllib
import typing
from dataclasses import asdict, fields
from pathlib import Path

import pytest

from drive_server.serving.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY, PreprocessContract
from models.data.trainingdata import DataOptions
from models.training.recipe import (
    NOT_IN_RECIPES,
    SECTIONS,
    bundled_recipes,
    load_recipe,
    recipe_sections,
    recipe_toml,
    renamed_sections,
    resolved,
)
from models.training.train_config import RENAMED, TrainConfig
from protocol.errors import BadValue
from tools.arguments import parse_speed
from tools.cli import BY_NAME, load, main, subcommand_parser

REPO = Path(__file__).resolve().parents[1]
PRETRAINED = REPO / "models" / "pretrained"
SAMPLE = REPO / "tests" / "data" / "udacity-sample"


def _fails(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one line ``rbc`` printed when it refused ``argv`` with exit code 2."""
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse's own exits
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    return err


def _recipe(tmp_path: Path, text: str, name: str = "x.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------------------------------------ the format
def test_every_config_field_has_one_place_and_the_config_keeps_the_defaults() -> None:
    keys = [key for section in SECTIONS.values() for key in section]
    assert len(keys) == len(set(keys)), "a key in two sections"
    assert sorted(keys + list(NOT_IN_RECIPES)) == sorted(f.name for f in fields(TrainConfig))
    defaults = load_recipe(None)
    assert asdict(defaults) == asdict(TrainConfig(data=[], out=""))


@pytest.mark.parametrize(("text", "said"), [
    ("[augmentation]\nyaw_gian = 3.0\n", "x.toml: [augmentation] yaw_gian: unknown key (known: aug_loops, "),
    ("[data]\nyaw_gain = 3.0\n", "x.toml: [data] yaw_gain: unknown key; did you mean [augmentation] yaw_gain?"),
    ("[data]\nsmooth_labels = 9\n", "[data] smooth_labels: unknown key; did you mean [data] label_smoothing_frames?"),
    ("[data]\nlabel_lag = 2\n", "[data] label_lag: unknown key; that knob was removed"),
    ("[augmentaton]\nyaw_gain = 3.0\n", "x.toml: [augmentaton]: unknown section (known: data, augmentation, "),
    ("yaw_gain = 3.0\n", "x.toml: yaw_gain: a key outside any section; did you mean [augmentation] yaw_gain?"),
    ("[augmentation]\nyaw_gain = \"3\"\n", '[augmentation] yaw_gain: wrong type: "3" is a string, not a number'),
    ("[training]\nepochs = 2.5\n", "x.toml: [training] epochs: wrong type: 2.5 is a number, not a whole number"),
    ("[export]\nmirror_average = 1\n", "[export] mirror_average: wrong type: 1 is a whole number, not true/false"),
    ("[network]\narch = \"resnet\"\n", '[network] arch: "resnet" is not one of "shallow", "pilotnet", '),
    ("[augmentation]\nyaw_gain = 9.0\n", "x.toml: yaw_gain must be 0..5, got 9.0"),
    ("[augmentation]\noffset_aug = 1.5\n", "x.toml: offset_aug must be 0..1, got 1.5"),
    ("[augmentation]\noffset_range = 0.0\n", "x.toml: offset_range must be above 0 and at most 4 m, got 0.0"),
    ("[augmentation]\noffset_lookahead = 0.5\n", "x.toml: offset_lookahead must be 1..100 m, got 0.5"),
    ("[augmentation]\noffset_range = \"2\"\n", 'offset_range: wrong type: "2" is a string, not a number'),
    ("[data\nsplit = 1\n", "x.toml: not valid TOML: "),
])
def test_a_wrong_recipe_is_refused_in_one_line_naming_the_file_and_key(tmp_path, capsys, text, said) -> None:
    recipe = _recipe(tmp_path, text)
    err = _fails(["train", "--recipe", str(recipe), "--data", str(SAMPLE), "--out", str(tmp_path / "run")], capsys)
    assert err.startswith("rbc train: error: ") and said in err, err
    assert not (tmp_path / "run").exists()


def test_the_moved_camera_keys_reach_the_augmentation(tmp_path) -> None:
    text = "[augmentation]\noffset_aug = 0.3\noffset_range = 1.5\noffset_lookahead = 8\n"
    config = load_recipe(str(_recipe(tmp_path, text)))
    augment = config.pipeline().augment
    assert (augment.offset_aug, augment.offset_range, augment.offset_lookahead) == (0.3, 1.5, 8.0)
    assert recipe_sections(config)["augmentation"]["offset_aug"] == 0.3
    assert load_recipe(None).pipeline().augment.offset_aug == 0.0  # off unless asked for


def test_a_whole_number_serves_where_a_number_is_asked(tmp_path) -> None:
    config = load_recipe(str(_recipe(tmp_path, "[augmentation]\nyaw_gain = 3\n")))
    assert config.yaw_gain == 3.0 and isinstance(config.yaw_gain, float)
    with pytest.raises(BadValue, match="^nowhere/x.toml: no such recipe file$"):
        load_recipe("nowhere/x.toml")


def test_an_unknown_recipe_name_lists_the_bundled_ones(capsys) -> None:
    err = _fails(["train", "--recipe", "unty", "--print"], capsys)
    assert "unknown recipe 'unty' (bundled: " in err
    assert all(name in err for name in ("collision", "generalist", "laps", "unity"))


# ------------------------------------------------------------------------------------------------ the command line
def test_print_shows_the_resolved_recipe_every_key_and_reads_back_as_the_same_run(tmp_path, capsys) -> None:
    assert main(["train", "--recipe", "unity", "--print"]) == 0  # no --data, no --out
    text = capsys.readouterr().out
    doc = tomllib.loads(text)
    assert {s: sorted(keys) for s, keys in doc.items()} == {s: sorted(keys) for s, keys in SECTIONS.items()}
    assert doc["augmentation"]["yaw_gain"] == 3.0 and doc["network"]["crop_top"] == 64
    assert doc["training"]["epochs"] == 6 and doc["augmentation"]["brightness_range"] == 0.5  # resolved, not None
    again = load_recipe(str(_recipe(tmp_path, text)))
    assert asdict(resolved(again)) == asdict(resolved(load_recipe("unity")))


def test_print_without_a_recipe_shows_the_defaults(capsys) -> None:
    assert main(["train", "--print"]) == 0
    doc = tomllib.loads(capsys.readouterr().out)
    assert doc["network"] == {"behavior": "simplistic", "arch": "shallow", "approach": "ours", "crop_top": 0,
                              "crop_bottom": 160, "decode_reduce": 0}
    assert (doc["data"]["split"], doc["training"]["export"], doc["training"]["epochs"]) == ("blocks", "best", 5)


def test_the_command_lines_epochs_and_seed_override_the_file(tmp_path, capsys) -> None:
    recipe = _recipe(tmp_path, "[training]\nepochs = 9\nseed = 4\nmax_steps_per_epoch = 7\n")
    assert main(["train", "--recipe", str(recipe), "--print"]) == 0
    assert tomllib.loads(capsys.readouterr().out)["training"] | {"learning_rate": 0} == {
        "epochs": 9, "seed": 4, "max_steps_per_epoch": 7, "batch_size": 256, "learning_rate": 0, "export": "best"}
    assert main(["train", "--recipe", str(recipe), "--epochs", "2", "--seed", "11", "--max-steps-per-epoch", "3",
                 "--print"]) == 0
    training = tomllib.loads(capsys.readouterr().out)["training"]
    assert (training["epochs"], training["seed"], training["max_steps_per_epoch"]) == (2, 11, 3)


#: Every flag of rbc train before recipes that now lives in them (or was removed).
OLD_FLAGS = ("--behavior", "--arch", "--approach", "--aug-loops", "--batch-size", "--split", "--balance-recordings",
             "--recovery-distance", "--yaw-aug", "--yaw-range", "--yaw-gain", "--label-lag", "--centre-gain",
             "--edge-gain", "--edge-margin", "--block-frames", "--gap-frames", "--export", "--mirror-average",
             "--output-scale", "--serve-smooth", "--crop-top", "--crop-bottom", "--decode-reduce", "--brightness-mode",
             "--brightness-range", "--min-speed", "--speed-unit", "--smooth-labels", "--row-stride",
             "--learning-rate")


@pytest.mark.parametrize("flag", OLD_FLAGS)
def test_a_flag_that_moved_into_recipes_says_where_it_went(flag, tmp_path, capsys) -> None:
    err = _fails(["train", "--data", str(SAMPLE), flag, "1", "--out", str(tmp_path / "run")], capsys)
    if flag in ("--label-lag", "--recovery-distance"):
        assert err == f"rbc train: error: {flag} was removed: it was measured useless (docs/experiments.md)"
    else:
        key = RENAMED.get(flag[2:].replace("-", "_"), flag[2:].replace("-", "_"))
        section = next(s for s, keys in SECTIONS.items() if key in keys)
        assert err.startswith(f"rbc train: error: {flag} moved into recipes: set [{section}] {key}"), err
        assert err.endswith("in a recipe file (rbc train --recipe FILE; rbc train --recipe unity --print shows one)")
    assert not (tmp_path / "run").exists()


def test_edge_gain_says_exactly_where_it_went(capsys) -> None:
    assert _fails(["train", "--edge-gain", "0.1"], capsys) == (
        "rbc train: error: --edge-gain moved into recipes: set [augmentation] edge_gain in a recipe file "
        "(rbc train --recipe FILE; rbc train --recipe unity --print shows one)")


def test_train_help_lists_at_most_15_options(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["train", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    options = [line for line in text.splitlines() if line.lstrip().startswith("-") and line.startswith("  -")]
    assert 8 <= len(options) <= 15, options
    for gone in ("--edge-gain", "--yaw-aug", "--mirror-average", "--behavior", "--arch", "--smooth-labels"):
        assert gone not in text
    assert "--recipe" in text and "--print" in text


def test_the_arguments_rbc_data_fold_prints_still_parse(capsys) -> None:
    from tools.realdata.recordings import fold_arguments, public_recordings

    argv = ["--recipe", "unity", *fold_arguments(public_recordings(), "real", "A"), "--out", "runs/cv-A"]
    args = subcommand_parser(BY_NAME["train"], load(BY_NAME["train"])).parse_args(argv)
    assert args.recipe == "unity" and args.data and args.val_data and args.out == "runs/cv-A"


def test_augment_preview_reads_a_recipe(tmp_path, capsys) -> None:
    pytest.importorskip("matplotlib")
    recipe = _recipe(tmp_path, '[network]\ncrop_top = 64\ncrop_bottom = 136\n\n[augmentation]\nyaw_aug = 0.5\n')
    out = tmp_path / "preview.png"
    assert main(["augment-preview", "--recipe", str(recipe), "--data", str(SAMPLE), "--out", str(out),
                 "--n", "2"]) == 0
    assert out.stat().st_size > 0 and "wrote" in capsys.readouterr().out
    err = _fails(["augment-preview", "--data", str(SAMPLE), "--out", str(out), "--yaw-aug", "0.5"], capsys)
    assert err.startswith("rbc augment-preview: error: --yaw-aug moved into recipes: set [augmentation] yaw_aug")


# ------------------------------------------------------------------------------------------------ stored runs
def test_a_stored_config_with_an_unknown_key_is_refused_in_one_line() -> None:
    with pytest.raises(BadValue, match=r"^run/config.json: unknown key 'yaw_gian' \(known: data, out, ") as exc:
        TrainConfig.from_dict({"data": ["x"], "out": "y", "yaw_gian": 3.0}, "run/config.json")
    assert "\n" not in str(exc.value)


def test_the_smoothing_key_has_one_name_and_recipes_written_before_still_load(tmp_path: Path) -> None:
    """Issue 51: [export] serve_smoothing is now smoothing (the name of the record and the model's metadata too)."""
    assert "\nserve_smoothing = 0.5" in (PRETRAINED / "unity.toml").read_text(encoding="utf-8")  # left as bundled
    assert load_recipe("unity").smoothing == 0.5
    assert "\nsmoothing = 0.5" in recipe_toml(load_recipe("unity"), "unity")
    new = tmp_path / "new.toml"
    new.write_text("[export]\nsmoothing = 0.25\n", encoding="utf-8")
    assert load_recipe(str(new)).smoothing == 0.25
    both = tmp_path / "both.toml"
    both.write_text("[export]\nsmoothing = 0.25\nserve_smoothing = 0.5\n", encoding="utf-8")
    with pytest.raises(BadValue, match="the same setting twice"):
        load_recipe(str(both))
    elsewhere = tmp_path / "elsewhere.toml"
    elsewhere.write_text("[training]\nserve_smoothing = 0.5\n", encoding="utf-8")
    with pytest.raises(BadValue, match=r"did you mean \[export\] smoothing"):
        load_recipe(str(elsewhere))


def test_a_config_stored_before_recipes_still_loads() -> None:
    """Written before #45: the removed knobs at their no-op values, the old names of two fields."""
    old = {"data": ["x"], "out": "y", "label_lag": 0, "recovery_distance": None, "smooth_labels": 9,
           "serve_smooth": 0.5, "split": "blocks", "export": "last"}
    config = TrainConfig.from_dict(old)
    assert (config.label_smoothing_frames, config.smoothing, config.split) == (9, 0.5, "blocks")
    assert TrainConfig.from_dict({**old, "serve_smoothing": 0.25}).smoothing == 0.25  # the name before the one
    with pytest.raises(BadValue, match="label_lag = 2: that knob was removed"):
        TrainConfig.from_dict({**old, "label_lag": 2})
    with pytest.raises(BadValue, match="recovery_distance = 5: that knob was removed"):
        TrainConfig.from_dict({**old, "recovery_distance": 5})


def test_the_data_options_carry_every_data_setting() -> None:
    config = load_recipe("unity", val_data=["v"])
    options = config.data_options()
    assert options == DataOptions(split=config.split_spec(), min_speed=5.0, min_speed_unit="mph", speed_unit="mph",
                                  label_smoothing_frames=9, row_stride=2, val_data=("v",), centre_gain=0.0,
                                  road_middles=True)


# ------------------------------------------------------------------------------------------------ bundled recipes
def test_bundled_recipes_resolve_and_no_name_is_taken_twice() -> None:
    names = [p.stem for folder in ("recipes", "pretrained") for p in (REPO / "models" / folder).glob("*.toml")]
    assert len(names) == len(set(names))
    assert set(bundled_recipes()) == set(names) >= {"laps", "unity", "simplistic"}
    for name in names:
        config = load_recipe(name)
        assert tomllib.loads(recipe_toml(config, name)) == recipe_sections(config)


def test_recipes_are_package_data() -> None:
    data = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert "*.toml" in data["*"]
    assert (REPO / "models" / "recipes" / "__init__.py").is_file() and (PRETRAINED / "__init__.py").is_file()
    assert "models/recipes *.toml" in (REPO / "MANIFEST.in").read_text()


def test_every_recipe_key_is_documented() -> None:
    page = (REPO / "docs" / "formats.md").read_text(encoding="utf-8")
    assert [key for keys in SECTIONS.values() for key in keys if f"`{key}`" not in page] == []
    assert [f"[{section}]" for section in SECTIONS if f"`[{section}]`" not in page] == []


def test_laps_is_the_unity_recipe_without_road_files_many_recordings_or_the_jungles_settings() -> None:
    """The moved camera and the stronger output were chosen for the jungle's hairpins across 35 drivers (#43);
    one's own laps of one track keep the plainer settings their page's figures were measured with."""
    laps, unity = recipe_sections(load_recipe("laps")), recipe_sections(load_recipe("unity"))
    differ = {(s, k) for s in SECTIONS for k in SECTIONS[s] if laps[s][k] != unity[s][k]}
    assert differ == {("augmentation", "edge_gain"), ("augmentation", "edge_margin"), ("data", "balance_recordings"),
                      ("augmentation", "offset_aug"), ("augmentation", "offset_range"), ("export", "gain")}
    assert laps["augmentation"]["edge_gain"] == 0.0 and not laps["data"]["balance_recordings"]
    assert laps["augmentation"]["offset_aug"] == 0.0 and unity["augmentation"]["offset_aug"] == 0.5


#: The rbc train line of each bundled model's card before recipes (their folders shortened), read below by the
#: old flags' meaning: the recipe must give the same configuration.
CARD_COMMANDS = {
    "simplistic": "--data data/simplistic --behavior simplistic --arch shallow --approach ours --split random "
                  "--export last --seed 0 --out runs/simplistic",
    "rigorous": "--data data/rigorous --behavior rigorous --arch shallow --approach ours --split random --export last "
                "--seed 0 --out runs/rigorous",
    "collision": "--data data/collision_multi --behavior collision --arch shallow --approach ours --split random "
                 "--export last --seed 0 --out runs/collision",
    "pilotnet_nvidia": "--data data/simplistic --behavior simplistic --arch pilotnet --approach nvidia --epochs 2 "
                       "--aug-loops 8 --split random --export last --seed 0 --out runs/pilotnet_nvidia",
    "pilotnet_ours": "--data data/simplistic --behavior simplistic --arch pilotnet --approach ours --epochs 2 "
                     "--aug-loops 8 --split random --export last --seed 0 --out runs/pilotnet_ours",
    "generalist_pilotnet": "--data data/generalist --behavior simplistic --arch pilotnet --approach ours --epochs 3 "
                           "--aug-loops 1 --row-stride 4 --split random --export last --seed 0 "
                           "--out runs/generalist_pilotnet",
    "generalist": "--data data/gen_default --data data/gen_udacity --data data/gen_udacity_wide "
                  "--data data/gen_default2 --val-data real/0xR4Y --val-data real/Alexishema --val-data real/2002Esala "
                  "--val-data real/A78345 "
                  "--val-data real/AdiJoost --val-data real/Dynaa --behavior simplistic --arch shallow --approach ours "
                  "--crop-top 64 --crop-bottom 136 --brightness-mode scale --min-speed 5mph --row-stride 2 "
                  "--aug-loops 8 --epochs 4 --export last --decode-reduce 2 --seed 0 --out runs/generalist",
    "unity": "--data real/0xR4Y --data real/2002Esala --out runs/unity --split blocks --crop-top 64 --crop-bottom 136 "
             "--brightness-mode scale --min-speed 5mph --smooth-labels 9 --balance-recordings --row-stride 2 "
             "--aug-loops 8 --epochs 6 --export last --arch shallow-wide --decode-reduce 2 --yaw-aug 0.5 --yaw-gain 3 "
             "--yaw-range 6 --edge-gain 0.1 --edge-margin 2.0 --offset-aug 0.5 --offset-range 3.0 --mirror-average "
             "--output-scale 1.5 --serve-smooth 0.5",
}
#: What a card does to the model after rbc train: generalist.onnx is rbc mirror --serve-smooth 0.5 of the run's.
AFTER_TRAINING = {"generalist": {"mirror_average": True, "smoothing": 0.5}}
#: Fields that say where the data is and how the machine ran, not what the model is.
NOT_RESULTS = ("data", "out", "threads", "decode_workers", "progress")


def _old_command(line: str) -> TrainConfig:
    """``rbc train`` arguments as the flags before recipes read them (a flag named after its field; ``--min-speed
    5mph`` sets the unit too; a true/false field is a switch)."""
    hints = typing.get_type_hints(TrainConfig)
    values: dict[str, typing.Any] = {"data": [], "val_data": []}
    argv = shlex.split(line)
    while argv:
        key = argv.pop(0)[2:].replace("-", "_")
        key = RENAMED.get(key, key)
        if key in ("data", "val_data"):
            values[key].append(argv.pop(0))
        elif key == "min_speed":
            values["min_speed"], values["min_speed_unit"] = parse_speed(argv.pop(0), "mph")
        elif hints[key] is bool:
            values[key] = True
        else:
            kind = next(t for t in typing.get_args(hints[key]) or (hints[key],) if t is not type(None))
            values[key] = kind(argv.pop(0))
    return TrainConfig(**values)


def _results(config: TrainConfig) -> dict[str, typing.Any]:
    return {k: v for k, v in asdict(resolved(config)).items() if k not in NOT_RESULTS}


@pytest.mark.parametrize("name", sorted(CARD_COMMANDS))
def test_a_bundled_models_recipe_is_its_cards_command(name) -> None:
    old = _old_command(CARD_COMMANDS[name])
    config = load_recipe(name, data=old.data, val_data=old.val_data, out=old.out)
    assert _results(config) == _results(old)
    card = (PRETRAINED / f"{name}.md").read_text(encoding="utf-8")
    assert f"rbc train --recipe {name} " in card, f"{name}.md's Reproduce names its recipe"


@pytest.mark.parametrize("name", sorted(CARD_COMMANDS))
def test_a_bundled_models_recipe_gives_what_its_onnx_file_records(name) -> None:
    """The ONNX record of the bundled models names the network, behavior, approach, seed, epochs, split, export,
    mirror, scale and smoothing, and its contract the crop, decode and blanked columns (so the yaw range); what it
    does not record (augmentation loops, speed filter, label smoothing...) the card's command above covers. A model
    whose record holds a whole recipe (trained after #45) is compared key by key."""
    import onnx

    proto = onnx.load(str(PRETRAINED / f"{name}.onnx"), load_external_data=False)
    meta = {p.key: p.value for p in proto.metadata_props}
    info = json.loads(meta[METADATA_MODEL_INFO_KEY])
    config = load_recipe(name, val_data=_old_command(CARD_COMMANDS[name]).val_data, **AFTER_TRAINING.get(name, {}))
    if "recipe" in info:
        assert renamed_sections(info["recipe"]) == recipe_sections(config)
        return
    full = resolved(config)
    recorded = {"arch": info["arch"], "behavior": info["behavior"], "approach": info["approach"], "seed": info["seed"],
                "epochs": info["epochs"], "split": info.get("split", "random"), "export": info.get("export", "last"),
                "mirror_average": info.get("mirror_average", False),
                "gain": info.get("gain", info.get("output_scale", 1.0)), "smoothing": info.get("serve_smooth", 1.0)}
    assert {k: getattr(full, k) for k in recorded} == recorded
    assert PreprocessContract.from_json(meta[METADATA_KEY]) == config.pipeline().contract


def test_every_bundled_model_has_a_recipe() -> None:
    models = sorted(p.stem for p in PRETRAINED.glob("*.onnx"))
    assert models == sorted(CARD_COMMANDS) == sorted(p.stem for p in PRETRAINED.glob("*.toml"))
