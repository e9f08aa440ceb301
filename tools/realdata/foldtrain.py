"""The fold models of a cross-validation by driver, trained from a recipe, each once.

Fold ``F``'s model is trained on every public recording outside ``F`` and validated on those in it, in
``RUNS/fold-F`` (what ``rbc train --recipe R $(rbc data fold F)`` does). A finished run (its model
exported and recorded) is never trained again; a run a stop interrupted continues from its checkpoint
(``rbc train --resume``: batch for batch the run it would have been), so a full cross-validation can be
spread over several sittings.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from models.networks.runfiles import CONFIG, MODEL
from tools.realdata.recordings import PublicRecording

#: Where fold F's run lives under the runs folder.
RUN_NAME = "fold-{fold}"


def fold_models(runs: Path) -> str:
    """The ``--models`` pattern of the fold runs under ``runs``."""
    return str(runs / RUN_NAME / MODEL)


def is_finished(run_dir: Path) -> bool:
    """The run exported its model and recorded the result (written last, after the model)."""
    try:
        return (run_dir / MODEL).is_file() and "result" in json.loads((run_dir / CONFIG).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False


def train_fold(recipe: str, fold: str, recordings: Sequence[PublicRecording], root: Path, runs: Path,
               progress: bool = True) -> Path | None:
    """Fold ``fold``'s model, trained (or its interrupted run continued) unless finished; None if a stop
    interrupted the training (its checkpoint is kept for the next sitting)."""
    from models.training.recipe import load_recipe
    from models.training.train import train

    run_dir = runs / RUN_NAME.format(fold=fold)
    if is_finished(run_dir):
        return run_dir / MODEL
    resume = (run_dir / CONFIG).is_file()
    data = [str(root / r.name) for r in recordings if r.fold != fold]
    val = [str(root / r.name) for r in recordings if r.fold == fold]
    config = load_recipe(recipe, data=data, val_data=val, out=str(run_dir), progress=progress)
    result = train(config, resume=resume)
    return None if result.interrupted else result.onnx
