"""A training knob's one declaration: a :class:`~models.training.train_config.TrainConfig` field made by :func:`knob`.

The field carries its default, the recipe section it lives in, what it is for, and the values it takes (a
:class:`Range` or a tuple of choices). Everything else is read from there: the recipe's sections and keys, the
range and choice checks with their one-line errors, the help that ``rbc train --print`` writes above each key
and ``rbc train --help`` lists. A field made without :func:`knob` is no recipe's: where the data is and how the
machine runs stay on the command line. Stdlib only, so the command line reads it without numpy or torch.
"""

from __future__ import annotations

import math
import re
from dataclasses import Field, dataclass, field, fields
from typing import TYPE_CHECKING, TypeVar

from protocol.errors import BadValue

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

    #: A config dataclass, or an instance of one.
    Config = DataclassInstance | type[DataclassInstance]

#: A recipe's sections, in the order a recipe file lists them.
SECTION_NAMES = ("data", "augmentation", "network", "training", "export")

T = TypeVar("T")
#: What a choice may be: a word or a whole number (a tuple of them: the values a key takes).
Choice = str | int


@dataclass(frozen=True)
class Range:
    """The values a number may take: ``low..high``, the low end itself excluded with ``low_open``."""

    low: float
    high: float = math.inf
    low_open: bool = False
    unit: str = ""

    def __contains__(self, value: object) -> bool:
        if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
            return False
        return (value > self.low if self.low_open else value >= self.low) and value <= self.high

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        if self.high == math.inf:
            return f"{'above' if self.low_open else 'at least'} {self.low:g}{unit}"
        if self.low_open:
            return f"above {self.low:g} and at most {self.high:g}{unit}"
        return f"{self.low:g}..{self.high:g}{unit}"


def knob(default: T, section: str, help: str, *, range: Range | None = None, choices: tuple[Choice, ...] = ()) -> T:
    """A config field that is a recipe key: its default, its section, what it is for, and its range or choices."""
    if section not in SECTION_NAMES:
        raise ValueError(f"knob section {section!r} is not one of {', '.join(SECTION_NAMES)}")
    meta = {"section": section, "help": help, "range": range, "choices": tuple(choices)}
    made: T = field(default=default, metadata=meta)
    return made


def knob_fields(config: Config) -> list[Field[object]]:
    """The knobs of a config class (or instance), in declaration order."""
    return [f for f in fields(config) if "section" in f.metadata]


def not_knobs(config: Config) -> tuple[str, ...]:
    """The fields of a config class that no recipe holds (the command line's)."""
    return tuple(f.name for f in fields(config) if "section" not in f.metadata)


def describe(f: Field[object]) -> str:
    """A knob's help with the values it takes: the comment above its key in a recipe ``rbc train --print`` writes,
    the help of a flag that overrides it."""
    meta = f.metadata
    if meta["range"] is not None:
        return f"{meta['help']} [{meta['range']}]"
    if not all(re.search(rf"\b{re.escape(str(c))}\b", meta["help"]) for c in meta["choices"]):
        return f"{meta['help']} [one of {', '.join(str(c) for c in meta['choices'])}]"
    return str(meta["help"])


def sections(config: Config) -> dict[str, dict[str, str]]:
    """Each recipe section of a config class and its keys, each with its help (:func:`describe`)."""
    found: dict[str, dict[str, str]] = {section: {} for section in SECTION_NAMES}
    for f in knob_fields(config):
        found[f.metadata["section"]][f.name] = describe(f)
    return {section: keys for section, keys in found.items() if keys}


def choices(config: Config) -> dict[str, tuple[Choice, ...]]:
    """The keys whose value is one of a few words or numbers, with those."""
    return {f.name: f.metadata["choices"] for f in knob_fields(config) if f.metadata["choices"]}


def check(config: DataclassInstance) -> None:
    """Every knob of ``config`` within its range and among its choices (None: the default's "none given"), else
    one line naming the key."""
    for f in knob_fields(config):
        value = getattr(config, f.name)
        allowed, among = f.metadata["range"], f.metadata["choices"]
        if value is None and f.default is None:
            continue
        if allowed is not None and value not in allowed:
            raise BadValue(f"{f.name} must be {allowed}, got {value!r}")
        if among and value not in among:
            raise BadValue(f"{f.name} must be one of {', '.join(str(c) for c in among)}, not {value!r}")
