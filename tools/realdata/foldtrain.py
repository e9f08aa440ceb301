"""The fold models of a cross-validation by driver, trained from a recipe, each once.

Fold ``F``'s model is trained on every public recording outside ``F`` and validated on those in it, in
``RUNS/fold-F`` (what ``rbc train --recipe R $(rbc data fold F)`` does). A finished run (its model
exported and recorded) is never trained again; a run a stop interrupted continues from its checkpoint
(``rbc train --resume``: batch for batch the run it would have been), so a full cross-validation can be
spread over several sittings. Both hold while the run's key holds (``fold.json``: the resolved recipe, the
recordings and their data, the training code found by following its imports); a run under another key is put
aside as ``fold-F.stale`` and trained afresh.
"""

from __future__ import annotations

import json
import logging
import shutil
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from models.networks.runfiles import RunPaths, RunRecord
from protocol.codeversion import ROOT, code_digest, data_digest
from protocol.errors import UserError
from protocol.runrecords import write_json
from tools.realdata.recordings import PublicRecording

if TYPE_CHECKING:
    from models.training.train_config import TrainConfig

log = logging.getLogger(__name__)

#: Where fold F's run lives under the runs folder.
RUN_NAME = "fold-{fold}"
#: The run's key, written before it trains: what its model depends on.
KEY_FILE = "fold.json"
#: Where the training starts (its code is this and all it imports) and the tree it is read from.
TRAIN_ENTRY = "models.training.train"
CODE_ROOT = ROOT
#: Settings that change how fast a run goes, not what it gives.
EXECUTION_ONLY = ("out", "threads", "decode_workers", "progress")


def fold_models(runs: Path) -> str:
    """The ``--models`` pattern of the fold runs under ``runs``."""
    return str(RunPaths(runs / RUN_NAME).model)


def is_finished(run_dir: Path) -> bool:
    """The run exported its model and recorded the result (written last, after the model)."""
    try:
        return RunRecord.load(run_dir).finished
    except (OSError, UserError):
        return False


def fold_key(config: TrainConfig) -> dict[str, object]:
    """Everything a fold's model depends on: the resolved settings (recordings by name, wherever they lie), each
    recording's data and the training code (:data:`TRAIN_ENTRY` and all it imports, under :data:`CODE_ROOT`)."""
    settings = {k: v for k, v in asdict(config).items() if k not in EXECUTION_ONLY}
    data = {part: {Path(d).name: data_digest([d]) for d in getattr(config, part)} for part in ("data", "val_data")}
    settings |= {part: sorted(names) for part, names in data.items()}
    return json.loads(json.dumps({"settings": settings, "data": data, "code": code_digest(TRAIN_ENTRY, root=CODE_ROOT)},
                                 sort_keys=True, default=str))


def _stored_key(run_dir: Path) -> dict[str, object] | None:
    try:
        return json.loads((run_dir / KEY_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def train_fold(recipe: str, fold: str, recordings: Sequence[PublicRecording], root: Path, runs: Path,
               progress: bool = True) -> Path | None:
    """Fold ``fold``'s model, trained (or its interrupted run continued) unless finished under the same
    :func:`fold_key`; None if a stop interrupted the training (its checkpoint is kept for the next sitting)."""
    from models.training.recipe import load_recipe
    from models.training.train import train

    run_dir = runs / RUN_NAME.format(fold=fold)
    data = [str(root / r.name) for r in recordings if r.fold != fold]
    val = [str(root / r.name) for r in recordings if r.fold == fold]
    config = load_recipe(recipe, data=data, val_data=val, out=str(run_dir), progress=progress)
    key = fold_key(config)
    stored = _stored_key(run_dir)
    if run_dir.is_dir() and any(run_dir.iterdir()) and stored != key:
        what = sorted(k for k in key if (stored or {}).get(k) != key[k]) if stored else ["an older version"]
        stale = run_dir.with_name(run_dir.name + ".stale")
        shutil.rmtree(stale, ignore_errors=True)
        run_dir.rename(stale)
        log.warning("%s was trained under other %s: trained afresh (the old run is in %s)", run_dir,
                    ", ".join(what), stale)
    if is_finished(run_dir):
        return RunPaths(run_dir).model
    resume = RunPaths(run_dir).config.is_file()
    write_json(run_dir / KEY_FILE, key)
    result = train(config, resume=resume)
    return None if result.interrupted else result.onnx
