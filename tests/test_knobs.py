"""Issue 51: a training knob is declared once, as a TrainConfig field made by ``knob`` (default, section, help,
range or choices), and the recipe's sections, the checks, the help and the mapping onto the pipeline are read
from there. Before, each knob lived in four or five places (the field, its range check, its section and help in
the recipe module, the copy into the augmentation, whose twin carried another name)."""

from __future__ import annotations

import math
import re
from dataclasses import MISSING, asdict, dataclass, fields
from pathlib import Path
from typing import Any

import pytest

from drive_server.serving.settings import check_gain
from drive_server.serving.smoothing import check_alpha
from models.augmentation.augment import AugmentSpec
from models.data.split import SplitSpec
from models.data.trainingdata import DataOptions
from models.training import knobs
from models.training.knobs import Range, knob
from models.training.recipe import SECTION_OF, SECTIONS, load_recipe, recipe_toml, resolved
from models.training.train_config import TrainConfig
from protocol.errors import BadValue

REPO = Path(__file__).resolve().parents[1]


@dataclass
class _Extended(TrainConfig):
    """TrainConfig with knobs added the one way: a field made by ``knob``, nothing else edited."""

    wobble: float = knob(0.25, "augmentation", "how far the test wobbles", range=Range(0.0, 1.0, unit="m"))
    mood: str = knob("calm", "network", "calm or wild", choices=("calm", "wild"))
    shadow: float = knob(AugmentSpec.shadow, "augmentation", "share of samples darkened by shadows",
                         range=Range(0.0, 1.0))  # named like an AugmentSpec field: it reaches the augmentation


def test_a_knob_declared_in_one_place_reaches_the_sections_the_help_the_checks_and_the_pipeline() -> None:
    sections = knobs.sections(_Extended)
    assert sections["augmentation"]["wobble"] == "how far the test wobbles [0..1 m]"
    assert sections["network"]["mood"] == "calm or wild" and knobs.choices(_Extended)["mood"] == ("calm", "wild")
    assert "wobble" not in knobs.not_knobs(_Extended) and knobs.not_knobs(_Extended) == knobs.not_knobs(TrainConfig)
    assert _Extended(data=[], out="").wobble == 0.25
    with pytest.raises(BadValue, match=r"^wobble must be 0..1 m, got 2.0$"):
        _Extended(data=[], out="", wobble=2.0)
    with pytest.raises(BadValue, match=r"^mood must be one of calm, wild, not 'angry'$"):
        _Extended(data=[], out="", mood="angry")
    assert TrainConfig(data=[], out="").pipeline().augment.shadow == 0.3  # the behavior's (Table 5)
    assert _Extended(data=[], out="", shadow=0.0).pipeline().augment.shadow == 0.0


def test_each_augmentation_setting_has_one_name_from_the_recipe_to_the_augmentation() -> None:
    """The recipe's yaw_aug, yaw_range, offset_aug, offset_range, offset_lookahead and edge_margin were yaw,
    yaw_range_deg, offset, offset_range_m, offset_lookahead_m and edge_margin_m in AugmentSpec."""
    spec = {f.name for f in fields(AugmentSpec)}
    assert set(SECTIONS["augmentation"]) - spec == {"aug_loops"}  # passes over the data, not a draw
    config = load_recipe("unity")
    augment = config.pipeline().augment
    assert {k: getattr(augment, k) for k in SECTIONS["augmentation"] if k in spec} == {
        "brightness_mode": "scale", "brightness_range": 0.5, "yaw_aug": 0.5, "yaw_range": 6.0, "yaw_gain": 3.0,
        "offset_aug": 0.5, "offset_range": 3.0, "offset_lookahead": 10.0, "edge_gain": 0.1, "edge_margin": 2.0}


def _differing_defaults(config: Any, other: Any) -> list[str]:
    """Knobs of ``config`` named like a field of ``other`` whose defaults differ (None: "the pipeline's own")."""
    theirs = {f.name: f.default for f in fields(other) if f.default is not MISSING}
    return [f"{f.name}: {f.default!r} here, {theirs[f.name]!r} in {other.__name__}" for f in knobs.knob_fields(config)
            if f.name in theirs and f.default is not None and f.default != theirs[f.name]]


def test_a_knob_named_like_a_field_below_keeps_its_default() -> None:
    for other in (AugmentSpec, DataOptions, SplitSpec):
        assert _differing_defaults(TrainConfig, other) == [], other

    @dataclass
    class Copied(TrainConfig):
        yaw_range: float = knob(8.0, "augmentation", "a copied and changed default")

    assert _differing_defaults(Copied, AugmentSpec) == ["yaw_range: 8.0 here, 6.0 in AugmentSpec"]


@pytest.mark.parametrize(("key", "serving_check"), [("gain", check_gain), ("smoothing", check_alpha)])
def test_the_serving_settings_range_is_the_servings_own(key: str, serving_check: Any) -> None:
    """A model file asks drive_server for its gain and smoothing: the recipe takes what the server takes."""
    allowed = next(f for f in fields(TrainConfig) if f.name == key).metadata["range"]
    for edge in (allowed.low, allowed.high):
        for value in (edge - 1e-9, edge, edge + 1e-9, math.nan):
            try:
                serving_check(value)
                served = True
            except ValueError:
                served = False
            assert (value in allowed) == served, (key, value)


def test_no_help_spells_a_range_by_hand() -> None:
    """The range is appended to the help from the declaration, so a help text that spells one holds a copy."""
    by_hand = re.compile(r"\d\s*\.\.\s*\d|<=|>=|\d\s*<|<\s*\d|(at most|at least) \d")
    assert [f.name for f in knobs.knob_fields(TrainConfig) if by_hand.search(f.metadata["help"])] == []
    assert "# largest turn of yaw_aug [above 0 and at most 30 degrees]\nyaw_range = 6.0\n" in recipe_toml(
        load_recipe("laps"), "laps")


def test_the_documented_defaults_are_the_declared_ones() -> None:
    """docs/formats.md's recipe table gives each key's default: a number or word there must be the declared one."""
    page = (REPO / "docs" / "formats.md").read_text(encoding="utf-8")
    defaults = asdict(resolved(load_recipe(None)))
    table = page[page.index("| section | key | default |"):].split("\n\n")[0]
    rows = [line.split("|")[1:-1] for line in table.splitlines() if "`" in line]
    checked = []
    for _, keys_text, default_text in rows:
        keys = [k for k in re.findall(r"`([a-z_]+)`", keys_text) if k in SECTION_OF]
        said = [d.strip() for d in default_text.split(", ")]
        if not keys:
            continue
        assert len(said) in (1, len(keys)), (keys, said)
        for key, text in zip(keys, said * len(keys) if len(said) == 1 else said, strict=True):
            word = re.fullmatch(r"`?([\w.]+)`?(?: \(off\))?", text)
            if word is None:  # in words ("the approach's")
                continue
            value = defaults[key]
            expected = str(value).lower() if isinstance(value, bool | str) else None
            assert (word[1] == expected) if expected is not None else math.isclose(float(word[1]), value), (key, text)
            checked.append(key)
    assert len(checked) >= 25, checked


def test_the_pipeline_is_built_once_for_each_setting_of_the_knobs() -> None:
    config = TrainConfig(data=[], out="")
    assert config.pipeline() is config.pipeline()
    config.yaw_aug = 0.5  # a knob changed after the config was made: built again, not stale
    assert config.pipeline().augment.yaw_aug == 0.5 and config.pipeline().contract.blank_columns > 0


def test_a_bundled_recipe_gives_the_config_it_gave_before_the_knobs_were_declared_once() -> None:
    """Frozen from the unity recipe before the change (every bundled recipe was compared whole then); keys added
    since at the value that trains as before."""
    config = load_recipe("unity")
    assert asdict(config) == {
        "approach": "ours", "arch": "shallow-wide", "aug_loops": 8, "balance_recordings": True, "batch_size": 256,
        "behavior": "simplistic", "block_frames": 50, "brightness_mode": "scale", "brightness_range": None,
        "centre_gain": 0.0, "crop_bottom": 136, "crop_top": 64, "data": [], "decode_reduce": 2,
        "decode_workers": None, "drop_turnround": False, "edge_gain": 0.1, "edge_margin": 2.0, "epochs": 6,
        "export": "last", "gain": 1.5,
        "gap_frames": 10, "label_smoothing_frames": 9, "learning_rate": 0.001, "max_steps_per_epoch": None,
        "min_speed": 5.0, "min_speed_unit": "mph", "mirror_average": True, "offset_aug": 0.5,
        "offset_lookahead": 10.0, "offset_range": 3.0, "out": "", "progress": True, "row_stride": 2, "seed": 0,
        "smoothing": 0.5, "speed_unit": "mph", "split": "blocks", "threads": None, "val_data": [],
        "val_fraction": 0.2, "yaw_aug": 0.5, "yaw_gain": 3.0, "yaw_range": 6.0}
    contract = config.pipeline().contract
    assert (contract.crop_top, contract.crop_bottom, contract.decode_reduce, contract.blank_columns) == (64, 136, 2, 13)
