"""Training recipes: TOML files that hold every setting of a run that shapes the model, by section.

A recipe's keys are :class:`TrainConfig` fields, and TrainConfig stays the one place of their defaults: this
module only says which section each key lives in (:data:`SECTIONS`), reads and checks a file (anything wrong is
one line naming the file and the key), finds the bundled recipes by name, and writes a config back as a recipe
(``rbc train --print``, the run's record, the recipe beside a model card). Where the data is and how the machine
runs it stay on the command line.
"""

from __future__ import annotations

import json
import tomllib
import typing
from dataclasses import replace
from pathlib import Path
from typing import Any

from drive_server.contract import DECODE_REDUCTIONS
from models.data.behavior import Approach, Arch
from models.data.split import SplitKind
from models.networks.runfiles import MODEL, RunRecord
from models.training.train_config import BRIGHTNESS_MODES, EXPORTS, REMOVED, RENAMED, RENAMED_IN_RECIPES, TrainConfig
from protocol.errors import BadValue
from protocol.facts import BEHAVIORS
from protocol.runrecords import write_text
from protocol.units import SpeedUnit

#: Each section of a recipe and its keys (TrainConfig fields), with why one would set the key.
SECTIONS: dict[str, dict[str, str]] = {
    "data": {
        "split": "held-out frames: blocks (stretches of each log), random (the paper's; optimistic at 9-15 Hz), "
                 "recordings (whole recordings: a new driver)",
        "val_fraction": "share of the data held out for validation",
        "block_frames": "frames per held-out block (split blocks; shortened for logs under 5 blocks)",
        "gap_frames": "training frames dropped on each side of a held-out block, so none is a near-copy of one",
        "min_speed": "drop rows recorded slower than this (laps start and end creeping; 0 keeps every row)",
        "min_speed_unit": "unit of min_speed: mph or kmh",
        "speed_unit": "unit of the log's speed column: mph (stock Udacity simulator) or kmh (the paper's)",
        "label_smoothing_frames": "fit a centred moving average of the steering over this many frames (keyboard "
                                  "taps averaged to what the driver meant; validation scores the recorded one). 0: off",
        "row_stride": "use every Nth row of the logs: neighbouring frames are near-copies, the frame cache shrinks",
        "balance_recordings": "each recording gives a pass over the data at most the median recording's samples",
        "centre_gain": "not in the paper: add this much steering per metre that the road's middle lies to the side "
                       "(every --data folder needs its road file, rbc data road). 0: off",
    },
    "augmentation": {
        "aug_loops": "passes over the training data per epoch, each drawing new augmentations (the paper's chi)",
        "brightness_mode": "add: the paper's p + beta (grey levels); scale: p * (1 + beta), relative to the frame",
        "brightness_range": "beta ~ U(-R, R): grey levels for add, a share of the pixel for scale (unset: the "
                            "mode's and the approach's)",
        "yaw_aug": "not in the paper: share of samples seen from the car turned, labelled to turn back (the "
                   "heading feedback a closed loop needs). 0: off",
        "yaw_range": "largest turn of yaw_aug, degrees",
        "yaw_gain": "how much of a turn yaw_aug's label steers back at once (1: aim along the road again)",
        "offset_aug": "not in the paper: share of centre-camera samples seen from the car moved sideways (DAVE-2's "
                      "shifts; the road re-projected through the ground plane), labelled to aim back. 0: off",
        "offset_range": "largest sideways move of offset_aug, metres (drawn uniformly in +-range)",
        "offset_lookahead": "metres ahead on the driver's line that offset_aug's label aims at (10: the side "
                            "cameras' Eq. 4/5)",
        "edge_gain": "not in the paper: steering per metre that a camera stands beyond edge_margin from the road's "
                     "middle, towards it (from road files; a recording without one is not pulled). 0: off",
        "edge_margin": "metres from the road's middle within which edge_gain pulls nothing",
    },
    "network": {
        "behavior": "simplistic, rigorous or collision: zero-steer balancing, augmentations and epochs (paper "
                    "Tables 4-6)",
        "arch": "shallow (the paper's CNN), pilotnet (NVIDIA's), shallow-wide (128x64, twice the filters)",
        "approach": "ours: the paper's balancing and augmentation; nvidia: crop, YUV, no balancing",
        "crop_top": "first row of the 320x160 frame the network sees (in the model's contract)",
        "crop_bottom": "row after the last one the network sees",
        "decode_reduce": "decode frames at 1/N size in training and drive_server alike; 0: the largest that keeps "
                         "the network's resolution",
    },
    "training": {
        "epochs": "passes of aug_loops x the training data (unset: the behavior's, the paper's Table 6)",
        "batch_size": "samples per step",
        "learning_rate": "Adam's step size",
        "seed": "split, balancing, augmentation and initialisation: the same seed and data give the same weights",
        "export": f"which epoch becomes {MODEL}: best (lowest validation MSE) or last",
        "max_steps_per_epoch": "cap on steps per epoch, for quick runs; 0: none",
    },
    "export": {
        "mirror_average": "not in the paper: the model answers (f(x) - f(mirror x)) / 2, its left-right noise "
                          "cancelled (not for a behavior that keeps to one lane); training is unchanged",
        "gain": "not in the paper, written into the model: drive_server multiplies the network's steering by this, "
                "0.1..2, unless its --gain says otherwise (above 1: the closed loop steers harder than the drivers' "
                "average); training, the network and its open-loop figures are unchanged",
        "smoothing": "written into the model: drive_server smooths each client's steering with this weight of "
                     "the new output, 0 < w <= 1 (1: off) unless its --smooth says otherwise",
    },
}
#: TrainConfig fields no recipe holds: where the data is and how this machine runs it (the command line's).
NOT_IN_RECIPES = ("data", "out", "val_data", "threads", "decode_workers", "progress")
#: Keys whose value is one of a few words or numbers.
CHOICES: dict[str, tuple[str | int, ...]] = {
    "split": tuple(k.value for k in SplitKind), "min_speed_unit": tuple(u.value for u in SpeedUnit),
    "speed_unit": tuple(u.value for u in SpeedUnit), "brightness_mode": BRIGHTNESS_MODES, "behavior": BEHAVIORS,
    "arch": tuple(a.value for a in Arch), "approach": tuple(a.value for a in Approach),
    "decode_reduce": DECODE_REDUCTIONS, "export": EXPORTS,
}
#: Where the bundled recipes are, searched in this order: general ones, then each bundled model's own.
RECIPE_DIRS = (Path(__file__).resolve().parents[1] / "recipes", Path(__file__).resolve().parents[1] / "pretrained")

#: Each key's section.
SECTION_OF = {key: section for section, keys in SECTIONS.items() for key in keys}
_TYPES = typing.get_type_hints(TrainConfig)
_KIND_WORDS = {bool: "true/false", int: "a whole number", float: "a number", str: "a string", list: "a list",
               dict: "a table"}


def bundled_recipes() -> dict[str, Path]:
    """Name -> file of every bundled recipe (models/recipes/*.toml, then models/pretrained/*.toml)."""
    found: dict[str, Path] = {}
    for folder in RECIPE_DIRS:
        for path in sorted(folder.glob("*.toml")):
            found.setdefault(path.stem, path)
    return found


def find_recipe(recipe: str) -> Path:
    """A recipe given as a path (it ends in .toml or names a folder) or as a bundled recipe's name."""
    path = Path(recipe).expanduser()
    if path.suffix == ".toml" or len(path.parts) > 1:
        if not path.is_file():
            raise BadValue(f"{recipe}: no such recipe file")
        return path
    bundled = bundled_recipes()
    if recipe not in bundled:
        raise BadValue(f"unknown recipe {recipe!r} (bundled: {', '.join(sorted(bundled))}; or give a .toml file)")
    return bundled[recipe]


def read_recipe(path: Path) -> dict[str, Any]:
    """The TrainConfig fields a recipe file sets, each checked for its section, name, type and choices."""
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise BadValue(f"{path}: not valid TOML: {exc}") from None
    values: dict[str, Any] = {}
    for section, table in doc.items():
        if not isinstance(table, dict):
            raise BadValue(f"{path}: {section}: a key outside any section{_belongs(section)} "
                           f"(sections: {', '.join(f'[{s}]' for s in SECTIONS)})")
        if section not in SECTIONS:
            raise BadValue(f"{path}: [{section}]: unknown section (known: {', '.join(SECTIONS)})")
        for old, value in table.items():
            new = RENAMED_IN_RECIPES.get(old, "")
            key = new if new in SECTIONS[section] else old
            if key != old and key in table:
                raise BadValue(f"{path}: [{section}] {old} and {key}: the same setting twice ({old} is its old name)")
            if key not in SECTIONS[section]:
                raise BadValue(f"{path}: [{section}] {key}: unknown key{_belongs(key, section)} "
                               f"(known: {', '.join(SECTIONS[section])})")
            values[key] = _checked(path, section, key, value)
    return values


def load_recipe(recipe: str | None, **overrides: Any) -> TrainConfig:
    """TrainConfig's defaults, then the recipe's settings (a path or a bundled name; None: none), then
    ``overrides`` (the command line's: data, out, seed...)."""
    path = None if recipe is None else find_recipe(recipe)
    values = {} if path is None else read_recipe(path)
    try:
        return TrainConfig(**{"data": [], "out": "", **values, **overrides})
    except ValueError as exc:  # a range or a combination: said with the file it came from
        raise BadValue(f"{path}: {exc}" if path else str(exc)) from None


def resolved(config: TrainConfig) -> TrainConfig:
    """The same run with every "the behavior's / the approach's" default (None) spelled out as its value."""
    p = config.pipeline()
    return replace(config, epochs=config.epochs or p.epochs, crop_top=p.contract.crop_top,
                   crop_bottom=p.contract.crop_bottom, brightness_range=p.augment.brightness_range,
                   max_steps_per_epoch=config.max_steps_per_epoch or 0)


def recipe_sections(config: TrainConfig) -> dict[str, dict[str, Any]]:
    """``config`` as a recipe, resolved: every key of every section (what the run record keeps)."""
    full = resolved(config)
    return {section: {key: _plain(getattr(full, key)) for key in keys} for section, keys in SECTIONS.items()}


def renamed_sections(sections: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Recorded recipe ``sections`` (a run's record, a model file's) with their keys in today's names."""
    return {section: {RENAMED.get(k, k): v for k, v in keys.items()} for section, keys in sections.items()}


def recipe_toml(config: TrainConfig, source: str | None = None) -> str:
    """``config`` as a recipe file: every key with what it is for (``rbc train --print``); read back, it gives
    the same run."""
    named = f"{source} ({find_recipe(source)})" if source else "none (the defaults)"
    header = [f"rbc train recipe: {named}, resolved: every key, defaults included."]
    return sections_toml(recipe_sections(config), header)


def sections_toml(sections: dict[str, dict[str, Any]], header: list[str]) -> str:
    """A recipe file of resolved ``sections``: ``header`` as comments, then every key with what it is for."""
    lines = [f"# {line}" for line in header]
    lines.append("# Read back with rbc train --recipe FILE; --data, --val-data, --out and --threads stay on the "
                 "command line.")
    for section, values in sections.items():
        lines += ["", f"[{section}]"]
        for key, value in values.items():
            lines += [f"# {SECTIONS[section][key]}", f"{key} = {_toml_value(value)}"]
    return "\n".join(lines) + "\n"


def run_recipe(run: RunRecord) -> dict[str, dict[str, Any]]:
    """A run's recipe, resolved, from its record (one written before records held it: from its config)."""
    if run.recipe is not None:
        return renamed_sections(run.recipe)
    return recipe_sections(TrainConfig.from_dict(run.config, str(run.config_path)))


def save_run_recipe(run: RunRecord, path: Path, header: list[str]) -> bool:
    """Write the run's resolved recipe to ``path`` (True); a recipe already there that gives the same run is kept
    as it is, comments and all (False); one that gives another run is an error, never overwritten."""
    sections = run_recipe(run)
    if path.exists():
        if recipe_sections(load_recipe(str(path))) != sections:
            raise BadValue(f"{path}: a recipe that gives another run than this one is already there",
                           "move it away, or write the card elsewhere (--out)")
        return False
    write_text(path, sections_toml(sections, header))
    return True


def _belongs(key: str, section: str | None = None) -> str:
    """Where a misplaced, renamed or removed key went, for the error line ('' if nowhere)."""
    if key in REMOVED:
        return "; that knob was removed (measured useless, docs/experiments.md)"
    new = RENAMED.get(key, key)
    if new in SECTION_OF and (new != key or SECTION_OF[new] != section):
        return f"; did you mean [{SECTION_OF[new]}] {new}?"
    return ""


def _checked(path: Path, section: str, key: str, value: Any) -> Any:
    """``value`` if it has the field's type (an integer serves as a number) and is one of its choices."""
    kinds = tuple(t for t in typing.get_args(_TYPES[key]) or (_TYPES[key],) if t is not type(None))
    ok = isinstance(value, kinds) and not (isinstance(value, bool) and bool not in kinds)
    if not ok and float in kinds and isinstance(value, int) and not isinstance(value, bool):
        value, ok = float(value), True
    if not ok:
        want = " or ".join(_KIND_WORDS[k] for k in kinds)
        raise BadValue(f"{path}: [{section}] {key}: wrong type: {json.dumps(value, default=str)} is "
                       f"{_KIND_WORDS.get(type(value), type(value).__name__)}, not {want}")
    if key in CHOICES and value not in CHOICES[key]:
        raise BadValue(f"{path}: [{section}] {key}: {json.dumps(value)} is not one of "
                       f"{', '.join(json.dumps(c) for c in CHOICES[key])}")
    return value


def _plain(value: Any) -> Any:
    """Enum members as their plain value, so the record and the TOML hold words."""
    return value.value if hasattr(value, "value") else value


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(str(value))  # a TOML basic string for the plain words recipes hold
