"""The run journal of ``rbc eval`` (``runs.jsonl``): who wrote it, and what a resumed evaluation may reuse.

A journaled run is reused by its task key (experiment, value, seed, scenario) when the journal's identity
(``journal.json``) is this evaluation's: the model file, the behavior, the driver, the track file and the code
that drives a run (:data:`RUN_ENTRY` and all it imports: the simulator, the drivers, the rules).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from protocol.codeversion import ROOT, code_digest
from protocol.runrecords import read_json, write_json, write_text
from tools.errors import CommandError
from tools.evaluate.evalrecord import EvalRun
from tools.evaluate.runner import DriverSpec, read_journal, spec_dict

log = logging.getLogger(__name__)

#: Where a run's record is made (:func:`tools.evaluate.runner.run_task`), and the tree its code is read from.
RUN_ENTRY = "tools.evaluate.runner"
CODE_ROOT = ROOT


def run_code() -> str:
    """The version of the code that drives a run: :data:`RUN_ENTRY` and all it imports."""
    return code_digest(RUN_ENTRY, root=CODE_ROOT)


def driver_identity(spec: DriverSpec) -> dict:
    """What of the driver decides the runs (not the model path or server URL, which may move)."""
    fields = {k: v for k, v in spec_dict(spec).items() if k not in ("model", "server")}
    return fields | {"mode": "socket" if spec.server else "in-process"}


def prepare_journal(out: Path, journal: Path, identity: dict, resume: bool) -> dict[str, EvalRun]:
    """Start a fresh journal, or (``--resume``) load the runs of an earlier one for the same model.

    ``journal.json`` beside the journal says which model and driver wrote it, so a resume never mixes
    runs of two models (or two versions of the code: :func:`run_code` joins ``identity``). A fresh start keeps an
    earlier journal as runs.previous.jsonl instead of deleting it.
    """
    identity = identity | {"code": run_code()}
    identity_file = out / "journal.json"
    reuse: dict[str, EvalRun] = {}
    if resume and journal.is_file():
        if identity_file.is_file():
            earlier = read_json(identity_file)
            if earlier != identity:
                diff = sorted(k for k in identity if earlier.get(k) != identity[k])
                raise CommandError(f"--resume: the journal in {out} was written for a different {', '.join(diff)}",
                                   "use a new --out, or drop --resume to start afresh")
        reuse = read_journal(journal)
        # rewrite it with the complete records only, so new runs never append to a line cut in half
        write_text(journal, "".join(json.dumps(r) + "\n" for r in reuse.values()))
        log.info("resuming: %d finished runs in %s", len(reuse), journal)
    elif resume:
        log.info("--resume: no journal in %s yet; starting afresh", out)
    elif journal.is_file() and journal.stat().st_size:
        journal.replace(out / "runs.previous.jsonl")
        log.info("starting afresh; the earlier journal is kept as %s (--resume would have reused it)",
                 out / "runs.previous.jsonl")
    write_json(identity_file, identity)
    return reuse
