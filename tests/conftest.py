"""Shared fixtures: small track files and tiny ONNX models built in the test session (no binary fixtures)."""

from __future__ import annotations

import json
import math
import signal
from pathlib import Path

import pytest

DATA = Path(__file__).parent / "data"

# A shell without job control starts background jobs with SIGINT ignored, and an ignored signal stays
# ignored in every child: the Ctrl-C tests' commands would never see their SIGINT. A handler here is
# reset to the default in each child at exec, so the children take Ctrl-C as a user's terminal sends it.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
UDACITY_SAMPLE = DATA / "udacity-sample"


def write_stadium(folder: Path, lanes: int = 1, road_width: float = 8.0, straight: float = 150.0,
                  radius: float = 40.0) -> str:
    """A stadium track file: two straights (the first going east) joined by two half circles."""
    h, r = straight / 2, radius
    arc = (-60, -30, 0, 30, 60)
    pts = [(-h + straight * k / 3, -r) for k in range(4)]
    pts += [(h + r * math.cos(math.radians(a)), r * math.sin(math.radians(a))) for a in arc]
    pts += [(h - straight * k / 3, r) for k in range(4)]
    pts += [(-h - r * math.cos(math.radians(a)), -r * math.sin(math.radians(a))) for a in arc]
    path = folder / f"stadium_{lanes}_{straight:g}_{radius:g}.json"
    path.write_text(json.dumps({"name": "stadium", "version": 1, "centerline": pts, "road_width": road_width,
                                "lanes": lanes, "start": {"s": 10.0}}))
    return str(path)


@pytest.fixture(scope="session")
def shallow_onnx(tmp_path_factory) -> Path:
    """The paper's shallow CNN with random weights, contract metadata included."""
    pytest.importorskip("onnx")
    from tools.bench.onnx_builders import save_model

    return save_model("shallow", tmp_path_factory.mktemp("models") / "shallow.onnx")
