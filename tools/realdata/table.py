"""The text table of ``rbc data stats``: one line per recording, then the total."""

from __future__ import annotations

from collections.abc import Sequence

from tools.realdata.stats import RecordingStats

#: (title, how to show a row's value). The steering's and speed's ranges are in --json; the line stays under 100
#: characters for the public recordings' names (the documentation shows it in a 100-column block).
_COLUMNS = (
    ("rows", lambda s: f"{s.rows}"),
    ("3-cam", lambda s: f"{s.rows_with_sides}"),
    ("missing", lambda s: f"{s.missing_images}"),
    ("Hz", lambda s: _num(s.frame_rate_hz, ".1f")),
    ("sessions", lambda s: f"{s.sessions}"),
    ("zero %", lambda s: _num(s.zero_steer_share, ".0%")),
    ("input", lambda s: s.input),
    ("r9", lambda s: _num(s.intent_r, ".2f")),
    ("<5mph", lambda s: _num(s.creep_share, ".0%")),
    ("dups", lambda s: f"{s.duplicates}"),
    ("sharp", lambda s: _num(s.sharpness, ".0f")),
)
#: The widest the table's lines are kept with two spaces between columns (else one).
MAX_WIDTH = 100
#: What each column says (rbc data stats --help).
COLUMN_HELP = (
    "rows: rows of the log; 3-cam: rows with all three frames; missing: frames the log names but the folder "
    "lacks; Hz: frames per second (from the time stamps in the frame names); sessions: stretches between pauses "
    "longer than --session-gap; zero %: rows steering exactly 0; input: keyboard (the steering mostly exactly 0 "
    "between taps) or mouse; r9: Pearson r of the steering with its own 9-frame average, what the driver meant "
    "(roughly the most r a model reaches on the recording); <5mph: % of rows recorded while creeping, which "
    "training leaves out; dups: rows repeating an earlier row's centre frame; sharp: mean Laplacian variance of "
    "--sharpness-frames centre frames, to compare graphics settings. --json also has the steering's and the "
    "speed's ranges")


def _num(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec).replace("%", "")


def format_table(rows: Sequence[RecordingStats], total: RecordingStats) -> str:
    """The table, with a rule above the total line; each column as wide as its title or widest value."""
    cells = [[r.name, *(show(r) for _, show in _COLUMNS)] for r in (*rows, total)]
    titles = ["recording", *(title for title, _ in _COLUMNS)]
    widths = [max(len(c[k]) for c in (titles, *cells)) for k in range(len(titles))]

    gap = 2 if sum(widths) + 2 * (len(widths) - 1) <= MAX_WIDTH else 1  # one space where two would not fit

    def line(values: Sequence[str]) -> str:
        return (" " * gap).join([f"{values[0]:<{widths[0]}}",
                                 *(f"{v:>{w}}" for v, w in zip(values[1:], widths[1:], strict=True))])

    head = line(titles)
    body = [line(c) for c in cells]
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
