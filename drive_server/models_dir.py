"""Where the bundled models live, found the same way in a source checkout and in an installed wheel."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from protocol.facts import BEHAVIORS

PRETRAINED_PACKAGE = "models.pretrained"
#: What drive_server and rbc demo serve without --model: the generalist, which matches the specialists on
#: their home tracks (README "Generalisation") and also drives roads it never saw.
DEFAULT_MODEL_NAME = "generalist_pilotnet.onnx"


def default_model_path() -> Path:
    """Path of the default bundled model (it may not exist yet: the caller checks)."""
    return Path(str(resources.files(PRETRAINED_PACKAGE) / DEFAULT_MODEL_NAME))


def bundled_model_path(behavior: str = "simplistic") -> Path:
    """Path of the bundled model of a driving behavior (simplistic, rigorous or collision)."""
    if behavior not in BEHAVIORS:
        raise ValueError(f"unknown behavior {behavior!r}; bundled models: {', '.join(BEHAVIORS)}")
    return Path(str(resources.files(PRETRAINED_PACKAGE) / f"{behavior}.onnx"))


def bundled_models() -> list[Path]:
    """Every bundled ONNX model, by name."""
    folder = resources.files(PRETRAINED_PACKAGE)
    return sorted(Path(str(folder / p.name)) for p in folder.iterdir() if p.name.endswith(".onnx"))
