"""Where the bundled models live, found the same way in a source checkout and in an installed wheel."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from protocol.errors import BadValue
from protocol.facts import BEHAVIORS

PRETRAINED_PACKAGE = "models.pretrained"
#: What drive_server serves without --model: the model trained on public recordings of the real Unity
#: simulator by many drivers (all three tracks), because a user beside Unity runs exactly that.
DEFAULT_MODEL_NAME = "unity.onnx"
#: What rbc demo (and the headless experiments' default driver) serves: the generalist of the headless
#: simulator, which matches the specialists on their home tracks and drives roads it never saw.
DEMO_MODEL_NAME = "generalist_pilotnet.onnx"


def default_model_path() -> Path:
    """Path of drive_server's default model (it may not exist yet: the caller checks)."""
    return Path(str(resources.files(PRETRAINED_PACKAGE) / DEFAULT_MODEL_NAME))


def demo_model_path() -> Path:
    """Path of the model ``rbc demo`` drives the headless simulator with."""
    return Path(str(resources.files(PRETRAINED_PACKAGE) / DEMO_MODEL_NAME))


def bundled_model_path(behavior: str = "simplistic") -> Path:
    """Path of the bundled model of a driving behavior (simplistic, rigorous or collision)."""
    if behavior not in BEHAVIORS:
        raise BadValue(f"unknown behavior {behavior!r}; bundled models: {', '.join(BEHAVIORS)}")
    return Path(str(resources.files(PRETRAINED_PACKAGE) / f"{behavior}.onnx"))


def bundled_models() -> list[Path]:
    """Every bundled ONNX model, by name."""
    folder = resources.files(PRETRAINED_PACKAGE)
    return sorted(Path(str(folder / p.name)) for p in folder.iterdir() if p.name.endswith(".onnx"))
