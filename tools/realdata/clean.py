"""A cleaned copy of a recording's log that points at the source frames (``rbc data clean``).

Only the log is written: its image paths are the absolute paths of the source frames, which
:func:`protocol.datalog.read_log` follows, so cleaning a recording of 20,000 frames copies none of them.
Every log is written to a temporary file and renamed into place, so a crash never leaves half a log.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from protocol.datalog import Sample, find_log, read_log
from protocol.datalog_writer import LOG_NAME, format_number
from protocol.rows import RowRange, row_numbers
from protocol.stamps import frame_time, session_ids
from protocol.units import to_kmh
from tools.errors import CommandError


@dataclass(frozen=True)
class CleanOptions:
    rows: RowRange | None = None  # keep only these rows of the source log (1-based, inclusive)
    min_speed_kmh: float = 0.0  # drop rows slower than this (0: none)
    min_speed_text: str = ""  # as the user gave it, e.g. 5mph
    speed_unit: str = "mph"  # unit of the log's speed column
    drop_duplicates: bool = False  # drop rows whose centre frame's file name an earlier row has
    split_sessions: bool = False  # one log per session (DST/session-01, ...)
    session_gap_s: float = 1.0


@dataclass
class CleanResult:
    read: int = 0  # data rows of the source log
    unusable: int = 0  # rows the reader skipped (bad numbers, missing centre frame)
    outside: int = 0
    slow: int = 0
    duplicates: int = 0
    logs: list[tuple[Path, int]] = field(default_factory=list)  # (log written, rows in it)

    @property
    def kept(self) -> int:
        return sum(n for _, n in self.logs)


def choose(samples: Sequence[Sample], rows: Sequence[int], options: CleanOptions,
           result: CleanResult) -> list[bool]:
    """Which samples to keep, counting each row dropped under the first reason that applies.

    A duplicate is a row whose centre frame's file name a row already kept has: one copy of each frame stays.
    """
    keep, kept_names = [], set()
    for s, row in zip(samples, rows, strict=True):
        if options.rows is not None and row not in options.rows:
            result.outside += 1
        elif options.min_speed_kmh > 0 and to_kmh(s.speed, options.speed_unit) < options.min_speed_kmh:
            result.slow += 1
        elif options.drop_duplicates and s.center.name in kept_names:
            result.duplicates += 1
        else:
            keep.append(True)
            kept_names.add(s.center.name)
            continue
        keep.append(False)
    return keep


def write_log(path: Path, samples: Sequence[Sample]) -> None:
    """A 7-column Udacity log without header, image paths absolute, through a temporary file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", encoding="utf-8", newline="") as fh:
        out = csv.writer(fh, lineterminator="\n")
        for s in samples:
            images = [str(p) if p is not None else "" for p in (s.center, s.left, s.right)]
            out.writerow(images + [format_number(v) for v in (s.steering, s.throttle, s.brake, s.speed)])
        fh.flush()
        os.fsync(fh.fileno())
    tmp.replace(path)


def check_destination(log: Path, dest: Path, force: bool) -> None:
    """Refuse to write into the source folder, or over a non-empty folder without ``force``."""
    if dest.exists() and not dest.is_dir():
        raise CommandError(f"{dest} exists and is not a folder")
    if dest.resolve() == log.resolve().parent:
        raise CommandError(f"{dest} is the source recording's folder", "give another --out")
    if dest.is_dir() and any(dest.iterdir()) and not force:
        raise CommandError(f"{dest} exists and is not empty", "choose a new --out, or add --force to replace its logs")


def clean(source: Path, dest: Path, options: CleanOptions, force: bool = False) -> CleanResult:
    """Write the cleaned log(s) of ``source`` under ``dest`` (``force``: over the logs a previous run left)."""
    log = find_log(source)
    check_destination(log, dest, force)
    samples, report = read_log(log)
    numbers = row_numbers(log)
    result = CleanResult(read=report.rows, unusable=len(report.skipped))
    keep = choose(samples, [numbers.get(s.line, 0) for s in samples], options, result)
    if not any(keep):
        raise CommandError(f"{log}: no row left, nothing written ({describe(result, options)})")
    if options.split_sessions:
        sessions = session_ids([frame_time(s.center.name) for s in samples], options.session_gap_s)
    else:
        sessions = [0] * len(samples)
    for session in sorted(set(sessions)):
        chosen = [s for s, k, n in zip(samples, keep, sessions, strict=True) if k and n == session]
        if chosen:  # numbered as in the source, so session-03 is the recording's third whatever was dropped
            path = dest / f"session-{session:02d}" / LOG_NAME if session else dest / LOG_NAME
            write_log(path, chosen)
            result.logs.append((path, len(chosen)))
    _remove_stale_logs(dest, {p for p, _ in result.logs})
    return result


def _remove_stale_logs(dest: Path, written: set[Path]) -> None:
    """Logs an earlier clean into ``dest`` wrote and this one did not (only with ``--force``)."""
    for old in [dest / LOG_NAME, *dest.glob(f"session-*/{LOG_NAME}")]:
        if old.is_file() and old not in written:
            old.unlink()
            if old.parent != dest and not any(old.parent.iterdir()):
                old.parent.rmdir()


def describe(result: CleanResult, options: CleanOptions) -> str:
    """The one line ``rbc data clean`` prints."""
    dropped = [f"{result.unusable} unusable"]
    if options.rows is not None:
        dropped.append(f"{result.outside} outside rows {options.rows}")
    if options.min_speed_kmh > 0:
        dropped.append(f"{result.slow} below {options.min_speed_text}")
    if options.drop_duplicates:
        dropped.append(f"{result.duplicates} duplicates")
    kept = f"kept {result.kept} of {result.read} rows, dropped {', '.join(dropped)}"
    if not result.logs:
        return kept
    if options.split_sessions:
        logs = ", ".join(f"{p.parent.name} ({n})" for p, n in result.logs)
        return f"{kept}; wrote {len(result.logs)} session logs under {result.logs[0][0].parent.parent}: {logs}"
    return f"{kept}; wrote {result.logs[0][0]}"
