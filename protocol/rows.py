"""1-based inclusive row ranges of a driving log (``1-2297``), and the data rows of a log file by number.

A public log sometimes holds two tracks one after the other; a row range is how it is split. Rows are
counted as :func:`protocol.datalog.read_log` counts them: non-blank lines, a header row not counted.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from protocol.datalog import is_header
from protocol.errors import BadValue


@dataclass(frozen=True)
class RowRange:
    first: int
    last: int

    def __contains__(self, row: int) -> bool:
        return self.first <= row <= self.last

    def __str__(self) -> str:
        return f"{self.first}-{self.last}"


def parse_rows(text: str) -> RowRange | None:
    """``"A-B"`` (1-based, inclusive) -> RowRange; empty -> None (every row)."""
    text = text.strip()
    if not text:
        return None
    m = re.fullmatch(r"(\d+)\s*-\s*(\d+)", text)
    if not m or not 1 <= int(m.group(1)) <= int(m.group(2)):
        raise BadValue(f"rows {text!r}: give a 1-based range FIRST-LAST with FIRST <= LAST, e.g. 1-2297")
    return RowRange(int(m.group(1)), int(m.group(2)))


def numbered_lines(lines: list[str]) -> Iterator[tuple[int, int, str]]:
    """(line number, row number, line) of each non-blank line; a header (first line only) has row number 0."""
    row, seen = 0, False
    for line_no, line in enumerate(lines, start=1):
        cells = [c.strip() for c in next(csv.reader([line], skipinitialspace=True), [])]
        if not any(cells):
            continue
        header, seen = not seen and is_header(cells), True
        if not header:
            row += 1
        yield line_no, 0 if header else row, line


def read_lines(log: Path) -> list[str]:
    """A log's lines as written (undecodable bytes kept as they are, for writing them back)."""
    text = log.read_text(encoding="utf-8-sig", errors="surrogateescape")  # newlines: \n, whatever was written
    return text.split("\n")[:-1] if text.endswith("\n") else text.split("\n")


def row_numbers(log: Path) -> dict[int, int]:
    """Line number -> row number of every data row of ``log``."""
    return {line: row for line, row, _ in numbered_lines(read_lines(log)) if row > 0}


def keep_rows(log: Path, rows: RowRange) -> int:
    """Rewrite ``log`` with its header (if any) and only the rows in ``rows``; returns the rows kept."""
    kept = [(row, line) for _, row, line in numbered_lines(read_lines(log)) if row == 0 or row in rows]
    tmp = log.with_name(log.name + ".tmp")
    tmp.write_text("".join(line + "\n" for _, line in kept), encoding="utf-8", errors="surrogateescape")
    tmp.replace(log)
    return sum(1 for row, _ in kept if row > 0)
