"""The public Udacity-simulator recordings this project trains and scores on, as data.

``public_recordings.csv`` names each recording once: the GitHub repository and commit that hold it, the
folder with the log and ``IMG/`` in it, the rows that belong to it (one log may hold two tracks, or
Udacity's sample beside the owner's rows), how its driver steered, its cross-validation fold and, where
it is not ``driving_log.csv``, the log's file name. The images are never committed here; ``rbc data
fetch`` gets them (and writes the log as ``driving_log.csv`` whatever its name in the repository).
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from protocol.datalog_writer import LOG_NAME
from protocol.errors import BadValue
from protocol.rows import RowRange, parse_rows

MANIFEST = "public_recordings.csv"
TRACKS = ("lake", "jungle", "mountain")
INPUTS = ("keyboard", "mouse")


@dataclass(frozen=True)
class PublicRecording:
    name: str  # unique; the folder ``rbc data fetch`` writes
    track: str  # lake, jungle or mountain
    repository: str  # GitHub owner/name
    commit: str  # 40 hex digits: the recording as it was, whatever the repository does later
    folder: str  # inside the repository, "" for its root, else ending in "/"
    rows: RowRange | None  # 1-based rows of the log that are this recording; None: all
    input: str  # keyboard or mouse
    # cross-validation fold (A-D): a driver's recordings share one, and every fold holds lake, several jungle
    # and one or more mountain recordings, so each is held out once from a model trained on all the others
    fold: str = ""
    log: str = LOG_NAME  # the log's file name in ``folder`` (the manifest's optional ``log`` column)
    notes: str = ""  # quirks a user of the recording should know (the manifest's optional ``notes`` column)

    def paths(self) -> tuple[str, str]:
        """The log and the image folder inside the repository."""
        return f"{self.folder}{self.log}", f"{self.folder}IMG"


def _parse(row: dict[str, str], line: int) -> PublicRecording:
    folder = row["folder"].strip().strip("/")
    rec = PublicRecording(name=row["name"].strip(), track=row["track"].strip(),
                          repository=row["repository"].strip(), commit=row["commit"].strip(),
                          folder=f"{folder}/" if folder else "", rows=parse_rows(row["rows"] or ""),
                          input=row["input"].strip(), fold=(row.get("fold") or "").strip(),
                          log=(row.get("log") or "").strip() or LOG_NAME, notes=(row.get("notes") or "").strip())
    if (rec.track not in TRACKS or rec.input not in INPUTS or len(rec.commit) != 40 or rec.repository.count("/") != 1
            or not rec.log.endswith(".csv") or any(c in rec.log for c in "/\\")):
        raise BadValue(f"{MANIFEST}:{line}: bad entry {rec}")
    return rec


def public_recordings() -> list[PublicRecording]:
    """Every entry of the manifest, in its order."""
    text = resources.files(__package__).joinpath(MANIFEST).read_text(encoding="utf-8")
    recs = [_parse(row, i) for i, row in enumerate(csv.DictReader(text.splitlines()), start=2)]
    names = [r.name for r in recs]
    if len(set(names)) != len(names):
        raise BadValue(f"{MANIFEST}: recording names repeat")
    return recs


def fold_arguments(recordings: Iterable[PublicRecording], root: str, fold: str) -> list[str]:
    """``rbc train`` arguments holding fold ``fold`` out: ``--data ROOT/NAME`` for the others, ``--val-data`` for it."""
    recordings = list(recordings)
    if fold not in {r.fold for r in recordings}:
        raise BadValue(f"unknown fold {fold!r}; folds: {', '.join(sorted({r.fold for r in recordings}))}")
    root = root.rstrip("/")
    return [a for r in recordings for a in ("--val-data" if r.fold == fold else "--data", f"{root}/{r.name}")]


def select(recordings: Iterable[PublicRecording], track: str | None = None,
           names: Iterable[str] | None = None) -> list[PublicRecording]:
    """The recordings on ``track`` (None: all) and named in ``names`` (None: all); an unknown name is an error."""
    recordings = list(recordings)
    wanted = list(names or [])
    unknown = sorted(set(wanted) - {r.name for r in recordings})
    if unknown:
        raise BadValue(f"unknown recording(s) {', '.join(unknown)}; known: {', '.join(r.name for r in recordings)}")
    return [r for r in recordings if (track is None or r.track == track) and (not wanted or r.name in wanted)]


def require_fetched(recordings: Iterable[PublicRecording], root: Path, what: str = "recordings") -> list[Path]:
    """Each recording's folder under ``root``; one missing (no ``driving_log.csv``) stops before any work."""
    from tools.errors import CommandError

    folders = [root / r.name for r in recordings]
    absent = [f.name for f in folders if not (f / "driving_log.csv").is_file()]
    if absent:
        raise CommandError(f"{len(absent)} {what} not under {root}, first {absent[0]}", f"rbc data fetch --out {root}")
    return folders
