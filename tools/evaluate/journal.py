"""The run journal of ``rbc eval`` (``runs.jsonl``): who wrote it, and what a resumed evaluation may reuse."""

from __future__ import annotations

import json
import logging
from pathlib import Path

from drive_server.runrecords import read_json, write_json, write_text
from tools.errors import CommandError
from tools.evaluate.runner import DriverSpec, read_journal, spec_dict

log = logging.getLogger(__name__)


def driver_identity(spec: DriverSpec) -> dict:
    """What of the driver decides the runs (not the model path or server URL, which may move)."""
    fields = {k: v for k, v in spec_dict(spec).items() if k not in ("model", "server")}
    return fields | {"mode": "socket" if spec.server else "in-process"}


def prepare_journal(out: Path, journal: Path, identity: dict, resume: bool) -> dict[str, dict]:
    """Start a fresh journal, or (``--resume``) load the runs of an earlier one for the same model.

    ``journal.json`` beside the journal says which model and driver wrote it, so a resume never mixes
    runs of two models. A fresh start keeps an earlier journal as runs.previous.jsonl instead of deleting it.
    """
    identity_file = out / "journal.json"
    reuse: dict[str, dict] = {}
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
