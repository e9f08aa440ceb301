"""``rbc model-card``: write the model card of a bundled model from its training run and a closed-loop check.

Used when (re)building ``models/pretrained``: ``rbc model-card RUN_DIR --behavior B --recipe "..."
--sim-json SIM_RESULT.json --out models/pretrained/B.md`` (library: :mod:`models.onnxfiles.model_card`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from drive_server.runrecords import read_json, write_text
from models.onnxfiles.model_card import card
from protocol.facts import BEHAVIORS


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="the rbc train run folder of the model")
    p.add_argument("--behavior", required=True, choices=BEHAVIORS, help="the behavior the model was trained for")
    p.add_argument("--recipe", required=True, help="the commands that rebuild the model, quoted in the card")
    p.add_argument("--sim-json", type=Path, required=True, help="rbc sim --json output of the no-variation lap")
    p.add_argument("--out", type=Path, required=True, help="card to write (models/pretrained/B.md)")


def run(a: argparse.Namespace) -> int:
    text = card(a.run_dir, a.behavior, a.recipe, read_json(a.sim_json), a.out.with_suffix(".onnx").name)
    write_text(a.out, text)
    return 0
