"""The text table of ``rbc data stats``: one line per recording, then the total."""

from __future__ import annotations

from collections.abc import Sequence

from tools.realdata.stats import RecordingStats

#: (title, width, how to show a row's value)
_COLUMNS = (
    ("rows", 6, lambda s: f"{s.rows}"),
    ("3-cam", 6, lambda s: f"{s.rows_with_sides}"),
    ("missing", 7, lambda s: f"{s.missing_images}"),
    ("Hz", 5, lambda s: _num(s.frame_rate_hz, ".1f")),
    ("sessions", 8, lambda s: f"{s.sessions}"),
    ("zero %", 6, lambda s: _num(s.zero_steer_share, ".0%")),
    ("input", 8, lambda s: s.input),
    ("steer min/max", 13, lambda s: _pair(s.steer_min, s.steer_max, "+.2f")),
    ("|s| p5/p95", 10, lambda s: _pair(s.abs_steer_p5, s.abs_steer_p95, ".2f")),
    ("r9", 4, lambda s: _num(s.intent_r, ".2f")),
    ("mph", 9, lambda s: _pair(s.speed_min_mph, s.speed_max_mph, ".0f", "-")),
    ("<5mph", 5, lambda s: _num(s.creep_share, ".0%")),
    ("dups", 5, lambda s: f"{s.duplicates}"),
    ("sharp", 6, lambda s: _num(s.sharpness, ".0f")),
)


def _num(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec).replace("%", "")


def _pair(a: float | None, b: float | None, spec: str, sep: str = "/") -> str:
    return "-" if a is None or b is None else f"{a:{spec}}{sep}{b:{spec}}"


def format_table(rows: Sequence[RecordingStats], total: RecordingStats) -> str:
    """The table, with a rule above the total line."""
    name_width = max(len("recording"), *(len(r.name) for r in (*rows, total)))

    def line(cells: Sequence[str]) -> str:
        return f"{cells[0]:<{name_width}}  " + " ".join(f"{c:>{w}}" for c, (_, w, _) in zip(cells[1:], _COLUMNS,
                                                                                             strict=True))

    head = line(["recording", *(title for title, _, _ in _COLUMNS)])
    body = [line([r.name, *(show(r) for _, _, show in _COLUMNS)]) for r in (*rows, total)]
    return "\n".join([head, "-" * len(head), *body[:-1], "-" * len(head), body[-1]])


def notes(total: RecordingStats) -> list[str]:
    """What the table leaves out but a user should know: rows the reader skipped, rows without a time stamp."""
    out = []
    if total.skipped_rows:
        out.append(f"{total.skipped_rows} rows skipped by the reader (bad numbers or a missing centre frame; "
                   "see the warnings above)")
    if total.undated_rows:
        out.append(f"{total.undated_rows} rows without a time stamp in the centre frame's name (left out of Hz "
                   "and sessions)")
    return out
