"""Writes driving logs exactly as the Udacity simulator does, in the column layout of :mod:`protocol.datalog`.

``driving_log.csv``: no header, ``", "`` separators, absolute image paths, numbers as C# prints them
(``0``, ``-0.2095149``, ``7.843922E-05``); frames in ``IMG/{camera}_YYYY_MM_DD_HH_MM_SS_mmm.jpg``.
Each row is one ``write`` straight to the file, so an interrupted recorder never leaves half a row, and a
write the disk cannot take (full: ENOSPC) is cut back to the last whole row before the error goes on.
Stdlib only.
"""

from __future__ import annotations

import csv
import datetime as dt
import os
from collections.abc import Sequence
from pathlib import Path

from protocol.appending import append_whole
from protocol.datalog import COLUMNS, positional_columns
from protocol.facts import CAMERAS

#: What a recorder writes (the reader also accepts the paper's ``Driving-Log.csv``).
LOG_NAME = "driving_log.csv"
IMAGE_DIR = "IMG"
_STAMP_FORMAT = "%Y_%m_%d_%H_%M_%S"


def format_number(x: float) -> str:
    """A number as Unity/C# writes it in the log: ``0``, ``-0.2095149``, ``7.843922E-05``."""
    if x == 0:
        return "0"
    return f"{x:.7g}".replace("e", "E")


def frame_stamp(when: dt.datetime) -> str:
    """The timestamp part of a frame's file name, millisecond resolution."""
    return when.strftime(_STAMP_FORMAT + "_") + f"{when.microsecond // 1000:03d}"


def frame_name(camera: str, when: dt.datetime) -> str:
    if camera not in CAMERAS:
        raise ValueError(f"camera must be one of {CAMERAS}, not {camera!r}")
    return f"{camera}_{frame_stamp(when)}.jpg"


def parse_frame_stamp(name: str) -> dt.datetime | None:
    """The time in a frame file name written by :func:`frame_name` (any folder prefix), or None."""
    stem = name.replace("\\", "/").rsplit("/", 1)[-1].rsplit(".", 1)[0].split("_", 1)[-1]
    try:
        return dt.datetime.strptime(stem[:-4], _STAMP_FORMAT) + dt.timedelta(milliseconds=int(stem[-3:]))
    except ValueError:
        return None


def format_row(images: Sequence[str], steering: float, throttle: float, brake: float, speed: float) -> str:
    """One log line (without the newline): up to three image paths, then the four numbers."""
    if not 1 <= len(images) <= 3:
        raise ValueError(f"a row has 1 to 3 images, got {len(images)}")
    cells = list(images) + [""] * (3 - len(images))
    return ", ".join(cells + [format_number(v) for v in (steering, throttle, brake, speed)])


def last_row_stamp(log_path: Path) -> dt.datetime | None:
    """Time of the last row of an existing log (to append after it), read from its centre frame's name."""
    if not Path(log_path).is_file():
        return None
    last: list[str] = []
    with Path(log_path).open(newline="", encoding="utf-8", errors="replace") as fh:
        for row in csv.reader(fh, skipinitialspace=True):
            if any(c.strip() for c in row):
                last = row
    if not last:
        return None
    try:
        column = positional_columns(len(last)).get(COLUMNS[0], 0)
    except ValueError:
        return None
    return parse_frame_stamp(last[column].strip())


class LogWriter:
    """Appends rows to a log, one unbuffered ``write`` per row (see the module docstring)."""

    def __init__(self, log_path: Path) -> None:
        self.path = Path(log_path)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
        self.rows = 0

    def write(self, images: Sequence[str], steering: float, throttle: float, brake: float, speed: float) -> None:
        append_whole(self._fd, (format_row(images, steering, throttle, brake, speed) + "\n").encode("utf-8"))
        self.rows += 1

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
