"""Result records: every figure on the documentation's Results page, written once, in ``results/NAME.json``.

A record is a small JSON file: what it measured (``title``), how (``runs``: each one command and the JSON
that command wrote, or a trimmed copy of it with the same keys), when (``date``), with which code
(``code_version``) and on which machine (``machine``). ``provenance`` is ``measured`` when this module ran
the commands itself (``python -m tools.results measure NAME``), or ``transcribed`` when the figures come from
a run whose output is not in the repository; ``source`` then says where they were taken from. ``command``
(optional) is the one line a table's caption names when a record holds several runs.

A page shows a record's table between two markers::

    <!-- results NAME TABLE -->
    (the table, generated)
    <!-- /results -->

The table's rows and columns are part of the record (``tables``), so the table is a function of the record
alone: the docs build (``tools/docsite.py``) renders it afresh, ``python -m tools.results write`` writes the
rendering into the page (so the Markdown reads the same on GitHub), and ``tests/test_results.py`` fails when a
page's table is not its record's rendering (a hand-edited figure, or a record changed without its page).

A column is ``[header, template]`` or ``[header, template, bold_if]``: ``template`` is a Python format string
over the row (``"{eta:.1f}"``, ``"{output[laps][0][eta]:.1f}"``; a value that is None prints as "–"), and
``bold_if`` names a true/false key of the row that makes the cell bold. A table whose ``caption`` is
``"short"`` (the second of a record's tables on a page) names only the record below it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shlex
import string
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "results"
DOCS = REPO / "docs"
#: ``<!-- results NAME TABLE -->`` ... ``<!-- /results -->``
BLOCK = re.compile(r"(<!-- results (?P<name>[\w-]+) (?P<table>[\w-]+) -->\n)(?P<body>.*?)(<!-- /results -->)", re.S)
PROVENANCES = ("measured", "transcribed")
REQUIRED = ("title", "provenance", "date", "code_version", "machine", "runs", "tables")
#: Paths the measured commands find in their working folder (a temporary one): the repository's models and
#: test data, and ``real/`` (where ``rbc data fetch --out real`` puts the public recordings).
LINKED = ("models", "tests")


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


def _path(record: dict[str, Any], dotted: str) -> Any:
    value: Any = record
    for part in dotted.split("."):
        value = value[int(part)] if isinstance(value, list) else value[part]
    return value


class _Cells(string.Formatter):
    """None prints as "–"; ``{key!y}`` prints a true/false value as yes/no."""

    def format_field(self, value: Any, format_spec: str) -> str:
        return "–" if value is None else super().format_field(value, format_spec)

    def convert_field(self, value: Any, conversion: str | None) -> Any:
        if conversion == "y":
            return None if value is None else ("yes" if value else "no")
        return super().convert_field(value, conversion)


_CELLS = _Cells()


def rows(record: dict[str, Any], table: dict[str, Any]) -> list[dict[str, Any]]:
    """The table's rows: ``rows`` is a dotted path into the record (default ``runs``), or a list of them,
    each a path or ``{"path": ..., "set": {key: value}}`` (the value added to each of its rows), concatenated;
    ``where`` keeps the rows whose keys have the given values."""
    spec = table.get("rows", "runs")
    found: list[dict[str, Any]] = []
    for part in spec if isinstance(spec, list) else [spec]:
        part = {"path": part} if isinstance(part, str) else part
        found += [{**row, **part.get("set", {})} for row in _path(record, part["path"])]
    where = table.get("where", {})
    return [row for row in found if all(row.get(k) == v for k, v in where.items())]


def render(record: dict[str, Any], table_name: str, name: str = "") -> str:
    """The Markdown of one of the record's tables, with the line that says where its figures come from."""
    try:
        table = record["tables"][table_name]
    except KeyError:
        raise RecordError(f"results/{name}.json: no table {table_name!r}") from None
    columns = table["columns"]
    lines = ["| " + " | ".join(col[0] for col in columns) + " |", "|" + "---|" * len(columns)]
    caption = (f"*The same record: `results/{name}.json`.*" if table.get("caption") == "short"
               else provenance_line(record, name))
    for row in rows(record, table):
        cells = []
        for col in columns:
            try:
                cell = _CELLS.vformat(col[1], (), row)
            except (KeyError, IndexError, TypeError, ValueError) as exc:
                raise RecordError(f"results/{name}.json, table {table_name}: {col[1]!r}: {exc!r}") from exc
            if len(col) > 2 and row.get(col[2]) and cell != "–":
                cell = f"**{cell}**"
            cells.append(cell.replace("|", "\\|"))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join([*lines, "", caption, ""])


def provenance_line(record: dict[str, Any], name: str) -> str:
    where = f"record `results/{name}.json`" if name else "its record"
    runs = record["runs"]
    command = record.get("command") or (runs[0]["command"] if len(runs) == 1 else f"{len(runs)} commands")
    line = f"*Measured {record['date']} ({record['code_version']}) by `{command}`"
    if record["provenance"] == "transcribed":
        line += f"; transcribed from {record['source']}"
    return f"{line}; {where}.*"


def blocks(text: str) -> Iterator[re.Match[str]]:
    return BLOCK.finditer(text)


def fill(text: str, root: Path = RESULTS) -> str:
    """``text`` with every results block rendered afresh from its record."""
    cache: dict[str, dict[str, Any]] = {}

    def one(match: re.Match[str]) -> str:
        name = match["name"]
        if name not in cache:
            cache[name] = load(name, root)
        return match.group(1) + render(cache[name], match["table"], name) + match.group(5)

    return BLOCK.sub(one, text)


def pages(docs: Path = DOCS) -> list[Path]:
    return sorted(docs.rglob("*.md"))


def write_pages(docs: Path = DOCS, root: Path = RESULTS) -> list[Path]:
    """Render every block of every page from its record; the pages that changed."""
    changed = []
    for page in pages(docs):
        text = page.read_text(encoding="utf-8")
        new = fill(text, root)
        if new != text:
            page.write_text(new, encoding="utf-8")
            changed.append(page)
    return changed


def stale(docs: Path = DOCS, root: Path = RESULTS) -> list[str]:
    """``page: NAME TABLE`` for every block whose text is not its record's rendering."""
    out = []
    for page in pages(docs):
        text = page.read_text(encoding="utf-8")
        for match in blocks(text):
            record = load(match["name"], root)
            if match["body"] != render(record, match["table"], match["name"]):
                out.append(f"{page.relative_to(docs.parent)}: {match['name']} {match['table']}")
    return out


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = f", load average {os.getloadavg()[0]:.1f} when measured" if hasattr(os, "getloadavg") else ""
    return f"{os.cpu_count()} cores ({cpu}), no GPU, {platform.system()} {platform.release().split('-')[0]}{load}"


def measure(name: str, real: Path | None = None, root: Path = RESULTS) -> dict[str, Any]:
    """Run a measured record's commands again and rewrite it with their output, the date, code and machine.

    Each command runs in a fresh temporary folder that links the repository's ``models/`` and ``tests/``
    (and ``real/`` to ``real``, where the public recordings are), so its paths read as a user types them.
    """
    from protocol.runrecords import code_version

    record = load(name, root)
    if record["provenance"] != "measured":
        raise RecordError(f"results/{name}.json is transcribed: there is no command to run here")
    where = machine()  # before the commands load it
    for run in record["runs"]:
        with tempfile.TemporaryDirectory(prefix="rbc-results-") as tmp:
            work = Path(tmp)
            for link in LINKED:
                (work / link).symlink_to(REPO / link)
            if real is not None:
                (work / "real").symlink_to(real.resolve())
            argv = shlex.split(run["command"])
            if argv[0] == "rbc":
                argv = [sys.executable, "-m", "tools.cli", *argv[1:]]
            print(f"$ {run['command']}", flush=True)
            start = time.monotonic()
            done = subprocess.run(argv, cwd=work, text=True, capture_output=True)
            if done.returncode not in run.get("exit_codes", [0]):
                raise RecordError(f"{run['command']}: exit {done.returncode}\n{done.stderr[-2000:]}")
            # paths the command wrote into its output read as the user typed them, not in the temporary folder
            text = (work / run["reads"]).read_text(encoding="utf-8").replace(f"{work}/", "")
            output = json.loads(text)
            keep = run.get("keep")
            run["output"] = {k: output[k] for k in keep if k in output} if keep else output
            print(f"  {time.monotonic() - start:.1f} s", flush=True)
    record.update(date=time.strftime("%Y-%m-%d"), code_version=code_version(), machine=where)
    (root / f"{name}.json").write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tools.results", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="action", required=True)
    m = sub.add_parser("measure", help="run a measured record's commands again and rewrite the record")
    m.add_argument("names", nargs="+", metavar="NAME")
    m.add_argument("--real", type=Path, default=None, help="where rbc data fetch put the public recordings")
    sub.add_parser("write", help="render every results block of docs/ from its record")
    sub.add_parser("check", help="exit 1 when a results block of docs/ is not its record's rendering")
    args = parser.parse_args(argv)
    if args.action == "measure":
        for name in args.names:
            measure(name, args.real)
        return 0
    if args.action == "write":
        for page in write_pages():
            print(f"wrote {page.relative_to(REPO)}")
        return 0
    wrong = stale()
    for line in wrong:
        print(f"stale: {line}")
    return 1 if wrong else 0


if __name__ == "__main__":
    raise SystemExit(main())
