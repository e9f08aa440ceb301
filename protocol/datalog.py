"""The driving-log format (Udacity ``driving_log.csv``, the paper's ``Driving-Log.csv``) and its tolerant reader.

Real logs are messy: no header or a header row (one naming the seven columns out of order was typed by
hand: they are read in the simulator's order), absolute Windows paths from another machine, ``", "``
separators, ``7.8E-05`` numbers, LF, CRLF or CR-only line ends, one camera (empty left/right fields) or
three. Only the file name of a recorded path is trusted: images are looked up next to the log
(``DIR/IMG/<name>`` first). Bad rows are skipped and reported with file and line so a broken recording
is noticed, never silently trained on. A missing or unreadable side frame (left/right) only costs that
row its sides: the centre frame and the label are still good, and copies of recordings often carry the
centre camera alone.
Stdlib only; the writer is :mod:`protocol.datalog_writer`.
"""

from __future__ import annotations

import csv
import logging
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath, PureWindowsPath

from protocol.errors import BadValue
from protocol.facts import IMAGE_MAGIC

log = logging.getLogger(__name__)

#: Log file names recognised when a directory is given (Udacity, the paper's simulator).
LOG_NAMES = ("driving_log.csv", "Driving-Log.csv")
#: Folders next to the log where frames are searched for by file name, in order.
IMAGE_DIRS = ("IMG", "Camera-Frames", ".")
#: Column order of a log without a header row (Udacity and the paper's simulator alike).
COLUMNS = ("center", "left", "right", "steering", "throttle", "brake", "speed")


class DataLogError(BadValue):
    """A driving log cannot be used at all (missing, empty, or no usable row)."""

    hint = "give a recording folder with driving_log.csv and IMG/, as rbc collect or the simulator writes"


@dataclass(frozen=True, slots=True)
class Sample:
    """One recorded time step. ``steering`` is normalised to -1..1 (x 25 degrees)."""

    center: Path
    left: Path | None
    right: Path | None
    steering: float
    throttle: float
    brake: float
    speed: float  # as recorded: mph (Udacity) or km/h (the paper's simulator)
    log: Path
    line: int

    @property
    def has_sides(self) -> bool:
        return self.left is not None and self.right is not None


@dataclass(frozen=True, slots=True)
class SkippedRow:
    line: int
    reason: str


@dataclass
class LogReport:
    """What happened to each row of one log: used or skipped (with line and reason).

    ``side_losses`` has one entry per side frame that was missing or unreadable; its row was used without
    sides (left = right = None).
    """

    log: Path
    rows: int = 0
    used: int = 0
    skipped: list[SkippedRow] = field(default_factory=list)
    side_losses: list[SkippedRow] = field(default_factory=list)

    @property
    def rows_without_sides(self) -> int:
        """Used rows that lost their side frames (a missing or unreadable left/right frame)."""
        return len({s.line for s in self.side_losses})

    def summary(self) -> str:
        text = f"{self.log}: {self.used} samples"
        if self.skipped:
            kinds = Counter(s.reason.split(":")[0] for s in self.skipped)
            first = self.skipped[0]
            detail = ", ".join(f"{k}: {n}" for k, n in kinds.most_common())
            text += (f", {len(self.skipped)} of {self.rows} rows skipped ({detail}); "
                     f"first: line {first.line}: {first.reason}")
        if self.side_losses:
            first = self.side_losses[0]
            text += (f"; {self.rows_without_sides} rows used without side frames; "
                     f"first: line {first.line}: {first.reason}")
        return text


@dataclass
class DataSet:
    """Samples of one or more logs in log order, with one report per log."""

    samples: list[Sample]
    reports: list[LogReport]

    @property
    def logs(self) -> list[Path]:
        return [r.log for r in self.reports]


def find_log(path: Path) -> Path:
    """A log file, or the log inside a recording directory."""
    path = Path(path)
    if path.is_file():
        return path
    if path.is_dir():
        for name in LOG_NAMES:
            if (path / name).is_file():
                return path / name
        csvs = sorted(path.glob("*.csv"))
        if len(csvs) == 1:
            return csvs[0]
        raise DataLogError(f"{path}: no {' or '.join(LOG_NAMES)} in this directory")
    raise DataLogError(f"{path}: no such file or directory")


def read_log(path: Path | str) -> tuple[list[Sample], LogReport]:
    """Read one log; rows with bad numbers or missing/unreadable images are skipped and reported."""
    log_path = find_log(Path(path)).resolve()
    report = LogReport(log_path)
    samples: list[Sample] = []
    resolver = _ImageResolver(log_path.parent)
    columns: dict[str, int] | None = None
    with log_path.open(newline="", encoding="utf-8-sig", errors="replace") as fh:
        for line_no, row in enumerate(csv.reader(fh, skipinitialspace=True), start=1):
            cells = [c.strip() for c in row]
            if not any(cells):
                continue
            if columns is None and report.rows == 0 and is_header(cells):
                columns = _header_columns(cells, log_path, line_no)
                continue
            report.rows += 1
            try:
                samples.append(_parse_row(cells, columns, resolver, log_path, line_no, report.side_losses))
            except _RowError as exc:
                report.skipped.append(SkippedRow(line_no, str(exc)))
    report.used = len(samples)
    if not samples:
        why = f" ({report.skipped[0].reason} at line {report.skipped[0].line})" if report.skipped else ""
        raise DataLogError(f"{log_path}: no usable samples in {report.rows} rows{why}")
    if report.skipped or report.side_losses:
        log.warning("%s", report.summary())
    return samples, report


def read_logs(paths: Iterable[Path | str]) -> DataSet:
    """Read and concatenate several logs (each a file or a recording directory)."""
    samples: list[Sample] = []
    reports: list[LogReport] = []
    for p in paths:
        s, r = read_log(p)
        samples.extend(s)
        reports.append(r)
    if not reports:
        raise DataLogError("no driving log given")
    return DataSet(samples, reports)


class _RowError(ValueError):
    pass


def is_header(cells: Sequence[str]) -> bool:
    """Whether the stripped cells of a log's first row are a header (its steering cell is not a number)."""
    try:
        float(cells[3] if len(cells) >= 7 else cells[1])
    except (ValueError, IndexError):
        return any(c.lower() in COLUMNS for c in cells)
    return False


def _header_columns(cells: Sequence[str], log_path: Path, line: int) -> dict[str, int]:
    names = {c.lower(): i for i, c in enumerate(cells)}
    missing = [c for c in ("center", "steering") if c not in names]
    if missing:
        raise DataLogError(f"{log_path}:{line}: header row lacks column(s) {missing}")
    if len(cells) == len(COLUMNS) and set(names) == set(COLUMNS) and list(names) != list(COLUMNS):
        # The simulators write these seven columns in this one order and no header: a header naming them in
        # another order was typed over such a log by hand (one public log has steering,speed,throttle,brake
        # over steering, throttle, brake and speed values), so the order wins over the names.
        log.info("%s:%d: header names the columns out of the simulator's order; read in its order", log_path, line)
        return positional_columns(len(COLUMNS))
    return {c: names[c] for c in COLUMNS if c in names}


def positional_columns(n: int) -> dict[str, int]:
    if n >= 7:
        return {c: i for i, c in enumerate(COLUMNS)}
    if n in (5, 6):  # one camera without the empty side fields: center, steering, throttle, brake, speed
        return {"center": 0, "steering": 1, "throttle": 2, "brake": 3, "speed": 4}
    if n == 4:  # three cameras and steering only
        return {"center": 0, "left": 1, "right": 2, "steering": 3}
    if n == 2:
        return {"center": 0, "steering": 1}
    raise _RowError(f"bad row: {n} fields")


def _number(cells: Sequence[str], columns: dict[str, int], name: str, required: bool) -> float:
    i = columns.get(name)
    text = cells[i] if i is not None and i < len(cells) else ""
    if not text:
        if required:
            raise _RowError(f"bad number: empty {name}")
        return 0.0
    try:
        value = float(text)
    except ValueError:
        raise _RowError(f"bad number: {name} {text[:30]!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise _RowError(f"bad number: {name} {text[:30]!r}")
    return value


def _parse_row(cells: list[str], columns: dict[str, int] | None, resolver: _ImageResolver, log_path: Path,
               line: int, side_losses: list[SkippedRow]) -> Sample:
    cols = columns if columns is not None else positional_columns(len(cells))
    steering = _number(cells, cols, "steering", required=True)
    if abs(steering) > 1.0 + 1e-6:
        raise _RowError(f"bad number: steering {steering} outside -1..1 (not normalised?)")
    paths: dict[str, Path | None] = {}
    losses: list[SkippedRow] = []
    for cam in ("center", "left", "right"):
        i = cols.get(cam)
        recorded = cells[i] if i is not None and i < len(cells) else ""
        if not recorded:
            if cam == "center":
                raise _RowError("missing image: no center frame recorded")
            paths[cam] = None
            continue
        try:
            paths[cam] = resolver.resolve(recorded)
        except _RowError as exc:
            if cam == "center":
                raise
            losses.append(SkippedRow(line, str(exc)))  # the row stays, without sides
            paths[cam] = None
    if (paths["left"] is None) != (paths["right"] is None):
        paths["left"] = paths["right"] = None  # one side only: perspective shifts need both
    center = paths["center"]
    assert center is not None
    sample = Sample(center=center, left=paths["left"], right=paths["right"], steering=max(-1.0, min(1.0, steering)),
                    throttle=_number(cells, cols, "throttle", False), brake=_number(cells, cols, "brake", False),
                    speed=_number(cells, cols, "speed", False), log=log_path, line=line)
    side_losses.extend(losses)  # only for rows that are used
    return sample


class _ImageResolver:
    """Finds a recorded frame next to the log by file name, whatever path the recorder wrote."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._listing: dict[Path, set[str]] = {}

    def _names(self, folder: Path) -> set[str]:
        if folder not in self._listing:
            try:
                self._listing[folder] = {p.name for p in folder.iterdir()} if folder.is_dir() else set()
            except OSError:
                self._listing[folder] = set()
        return self._listing[folder]

    def resolve(self, recorded: str) -> Path:
        is_windows = "\\" in recorded or (len(recorded) > 1 and recorded[1] == ":")
        pure = PureWindowsPath(recorded) if is_windows else PurePosixPath(recorded)
        name = pure.name
        candidates = [self.root / d / name for d in IMAGE_DIRS if name in self._names(self.root / d)]
        if not pure.is_absolute():
            candidates.append(self.root / Path(*pure.parts))
        elif not is_windows:
            candidates.append(Path(recorded))
        for c in candidates:
            if c.is_file():
                _check_readable(c)
                return c.resolve()
        raise _RowError(f"missing image: {name} (recorded as {recorded[:120]})")


def _check_readable(path: Path) -> None:
    try:
        with path.open("rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise _RowError(f"unreadable image: {path.name} ({exc.strerror})") from None
    if not head.startswith(IMAGE_MAGIC):
        raise _RowError(f"unreadable image: {path.name} is not a JPEG/PNG")
