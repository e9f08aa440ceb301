"""Training recipes: TOML files that hold every setting of a run that shapes the model, by section.

A recipe's keys are :class:`TrainConfig`'s knobs, each declared once there (default, section, help, range or
choices; :mod:`models.training.knobs`): this module reads and checks a file by them (anything wrong is one line
naming the file and the key), finds the bundled recipes by name, and writes a config back as a recipe (``rbc train
--print``, the run's record, the recipe beside a model card). Where the data is and how the machine runs it stay on
the command line.
"""

from __future__ import annotations

import json
import tomllib
import typing
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from models.networks.runfiles import RunRecord
from models.training import knobs
from models.training.train_config import ADDED_TO_RECIPES, REMOVED, RENAMED, RENAMED_IN_RECIPES, TrainConfig
from protocol.errors import BadValue
from protocol.runrecords import write_text

#: Each section of a recipe and its keys (TrainConfig's knobs), with why one would set the key and what it takes.
SECTIONS: dict[str, dict[str, str]] = knobs.sections(TrainConfig)
#: TrainConfig fields no recipe holds: where the data is and how this machine runs it (the command line's).
NOT_IN_RECIPES = knobs.not_knobs(TrainConfig)
#: Keys whose value is one of a few words or numbers.
CHOICES: dict[str, tuple[str | int, ...]] = knobs.choices(TrainConfig)
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


def read_recipe(path: Path) -> dict[str, object]:
    """The TrainConfig fields a recipe file sets, each checked for its section, name, type and choices."""
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise BadValue(f"{path}: not valid TOML: {exc}") from None
    values: dict[str, object] = {}
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


def recipe_sections(config: TrainConfig) -> dict[str, dict[str, object]]:
    """``config`` as a recipe, resolved: every key of every section (what the run record keeps)."""
    full = resolved(config)
    return {section: {key: _plain(getattr(full, key)) for key in keys} for section, keys in SECTIONS.items()}


def renamed_sections(sections: Mapping[str, Mapping[str, object]]) -> dict[str, dict[str, object]]:
    """Recorded recipe ``sections`` (a run's record, a model file's) with their keys in today's names, and the keys
    added since with what the run did without them."""
    out = {section: {RENAMED.get(k, k): v for k, v in keys.items()} for section, keys in sections.items()}
    for key, value in ADDED_TO_RECIPES.items():
        if SECTION_OF[key] in out:
            out[SECTION_OF[key]].setdefault(key, value)
    return out


def recipe_toml(config: TrainConfig, source: str | None = None) -> str:
    """``config`` as a recipe file: every key with what it is for (``rbc train --print``); read back, it gives
    the same run."""
    named = f"{source} ({find_recipe(source)})" if source else "none (the defaults)"
    header = [f"rbc train recipe: {named}, resolved: every key, defaults included."]
    return sections_toml(recipe_sections(config), header)


def sections_toml(sections: Mapping[str, Mapping[str, object]], header: list[str]) -> str:
    """A recipe file of resolved ``sections``: ``header`` as comments, then every key with what it is for."""
    lines = [f"# {line}" for line in header]
    lines.append("# Read back with rbc train --recipe FILE; --data, --val-data, --out and --threads stay on the "
                 "command line.")
    for section, values in sections.items():
        lines += ["", f"[{section}]"]
        for key, value in values.items():
            lines += [f"# {SECTIONS[section][key]}", f"{key} = {_toml_value(value)}"]
    return "\n".join(lines) + "\n"


def run_recipe(run: RunRecord) -> dict[str, dict[str, object]]:
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


def _checked(path: Path, section: str, key: str, value: object) -> object:
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


def _plain(value: object) -> object:
    """Enum members as their plain value, so the record and the TOML hold words."""
    return value.value if hasattr(value, "value") else value


def _toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(str(value))  # a TOML basic string for the plain words recipes hold
