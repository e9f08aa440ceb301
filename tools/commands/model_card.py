"""``rbc model-card``: a model's card and, beside it, the resolved recipe that rebuilds it, from its training run.

``rbc model-card runs/foo --model models/pretrained/foo.onnx`` writes ``models/pretrained/foo.md`` (what it is,
how to use it, how to measure it, how to rebuild it; no result figures) and ``models/pretrained/foo.toml``
(library: :mod:`models.onnxfiles.model_card`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from models.networks.runfiles import MODEL
from tools.errors import CommandError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="the rbc train run folder of the model")
    p.add_argument("--model", type=Path, metavar="M.onnx",
                   help=f"the model file the card describes, e.g. an rbc mirror copy (default: RUN_DIR/{MODEL})")
    p.add_argument("--out", type=Path, metavar="CARD.md",
                   help="card to write (default: beside the model, NAME.md); the recipe goes beside it, CARD.toml")
    p.add_argument("--purpose", help="the card's one-line purpose (default: one said from the run)")
    p.add_argument("--data-command", action="append", metavar="CMD",
                   help="a command that made the model's data (rbc collect ...), quoted before rbc train in the "
                        "card's Reproduce (repeat; default: none, the card says where such data comes from)")


def run(a: argparse.Namespace) -> int:
    from models.networks.runfiles import RunRecord
    from models.onnxfiles.model_card import CardSource, card, read_model_file
    from models.training.recipe import bundled_recipes, save_run_recipe
    from protocol.runrecords import write_text

    record = RunRecord.load(a.run_dir)
    model = a.model or record.model_path
    out = a.out or model.with_suffix(".md")
    if record.result is None:
        raise CommandError(f"{a.run_dir}: the run has exported no model yet", "finish it: rbc train --resume")
    if not model.is_file():
        raise CommandError(f"no model at {model}", "give --model, the file the card describes")
    if out.suffix != ".md":
        raise CommandError(f"--out {out}: give a path ending in .md")
    recipe, model_file = out.with_suffix(".toml"), read_model_file(model)
    written = save_run_recipe(record, recipe, [f"The recipe of {model.name}, resolved from its run "
                                               f"{a.run_dir.as_posix()}: every key, defaults included.",
                                               f"Its card, {out.name}, has the commands that rebuild it."])
    bundled = recipe.stem if bundled_recipes().get(recipe.stem) == recipe.resolve() else ""
    source = CardSource(record, model_file, recipe, _home(record.config["behavior"]), a.purpose or "",
                        tuple(a.data_command or ()), bundled)
    write_text(out, card(source))
    print(f"wrote {out}; recipe {recipe} {'written' if written else 'kept (it gives the same run)'}")
    return 0


def _home(behavior: str) -> str:
    """``rbc sim``'s flags for the behavior's scene: its track and, for collision avoidance, its cones."""
    from tools.evaluate.experiments import SETUPS

    s = SETUPS[behavior]
    return f"--track {s.track}" + (f" --cones {s.cones} --cone-seed {s.cone_seed}" if s.cones else "")
