"""A result record read and checked (``results/NAME.json``), and the line that says where its figures come from.

The rest of :mod:`tools.results` renders, writes and measures records; this module is what they all read: where
the records and pages are, what a record must hold, and its code version and machine in short.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "results"
DOCS = REPO / "docs"
PROVENANCES = ("measured", "transcribed")
REQUIRED = ("title", "provenance", "date", "code_version", "machine", "runs", "tables")


class RecordError(ValueError):
    """A record that cannot be read or rendered, named."""


def load(name: str, root: Path = RESULTS) -> dict[str, Any]:
    path = root / f"{name}.json"
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise RecordError(f"results/{name}.json: {exc}") from exc
    missing = [key for key in REQUIRED if key not in record]
    if missing:
        raise RecordError(f"results/{name}.json: missing {', '.join(missing)}")
    if record["provenance"] not in PROVENANCES:
        raise RecordError(f"results/{name}.json: provenance must be one of {PROVENANCES}")
    if record["provenance"] == "transcribed" and not record.get("source"):
        raise RecordError(f"results/{name}.json: a transcribed record says where from (source)")
    return record


def names(root: Path = RESULTS) -> list[str]:
    return sorted(p.stem for p in root.glob("*.json"))


def code_version(record: dict[str, Any]) -> str:
    """The code version, short: ``git`` and the commit, and whether there were uncommitted edits (the
    record keeps the whole of it)."""
    version = str(record["code_version"])
    match = re.match(r"git ([0-9a-f]{7,40})(-dirty)?(.*)", version)
    if not match:
        return version
    edits = " with uncommitted edits" if match[2] or match[3].strip() else ""
    return f"`{match[1][:7]}`{edits}"


def machine_short(record: dict[str, Any]) -> str:
    """The machine, short: its cores and GPU (the record keeps the operating system and the load)."""
    return re.split(r", (?:Linux|load)|: ", str(record["machine"]))[0]


def provenance_line(record: dict[str, Any], name: str) -> str:
    """Where a table's figures come from, in one line: the command, the code version, the machine."""
    runs = record["runs"]
    command = record.get("command") or (runs[0]["command"] if len(runs) == 1 else f"{len(runs)} commands")
    line = f"*`{command}` · code {code_version(record)} · {machine_short(record)}"
    where = f"`results/{name}.json`" if name else "its record"
    if record["provenance"] == "transcribed":
        where += ", transcribed"
    return f"{line} · {where}*"
