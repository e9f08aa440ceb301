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

A column is ``[header, template]``, ``[header, template, bold_if]`` or ``[header, template, {options}]``:
``template`` is a Python format string over the row (``"{eta:.1f}"``, ``"{output[laps][0][eta]:.1f}"``; a
value that is None prints as "–", ``{path!b}`` prints a path's file name); ``bold_if`` (option ``bold``)
names a true/false key of the row (dotted: ``peer.beats_zero``) that makes the cell bold; option ``per``
names the count a rate is of (``{"per": "interventions"}`` on "s per take-over"): where the count is 0
the cell prints "–", as a rate of nothing is no figure.

A table's ``join`` adds to each row, under a name, the matching row of other rows, of this record or of
another one (``record``), matched on a key (``on``); with ``mean`` (``{name: dotted path}``) it adds the
mean over every matching row instead, and their count as ``n``. A table with ``"csv": true`` is not
shown on a page: ``write`` writes it to ``docs/data/NAME-TABLE.csv`` (every column, no rounding beyond its
template), for a page to link.

A line under the table says where its figures come from: the command, the code version and the machine
(and the record). A page says it once per section (``##``) and record: a later table of the same record in
the same section has no line. A table whose ``caption`` is ``"records"`` names only its records.
"""

from __future__ import annotations

import argparse
import csv
import io
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
#: Where ``write`` puts the tables a page offers as CSV files (``"csv": true``).
CSV_FOLDER = "data"
NONE = "–"
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


def _path(record: Any, dotted: str) -> Any:
    value: Any = record
    for part in dotted.split("."):
        value = value[int(part)] if isinstance(value, list) else value[part]
    return value


def _get(row: dict[str, Any], dotted: str) -> Any:
    """A row's value at a dotted key, None where it has none."""
    try:
        return _path(row, dotted)
    except (KeyError, IndexError, TypeError, ValueError):
        return None


class _Cells(string.Formatter):
    """None prints as "–"; ``{key!y}`` prints a true/false value as yes/no, ``{key!b}`` a path's file name."""

    def format_field(self, value: Any, format_spec: str) -> str:
        return NONE if value is None else super().format_field(value, format_spec)

    def convert_field(self, value: Any, conversion: str | None) -> Any:
        if conversion == "y":
            return None if value is None else ("yes" if value else "no")
        if conversion == "b":
            return None if value is None else Path(str(value)).name
        return super().convert_field(value, conversion)


_CELLS = _Cells()


def _options(column: list[Any]) -> dict[str, Any]:
    """A column's options: its third element, a key to bold by or a dict."""
    if len(column) < 3 or column[2] is None:
        return {}
    return {"bold": column[2]} if isinstance(column[2], str) else dict(column[2])


class _Nothing(dict[str, Any]):
    """What a join found where no row matched: every key of it is None (it prints as "–")."""

    def __getitem__(self, key: str) -> None:
        return None


def _joined(row: dict[str, Any], spec: dict[str, Any], source: list[dict[str, Any]]) -> Any:
    key = spec["on"]
    matching = [other for other in source if _get(other, key) == _get(row, key)]
    if "mean" not in spec:
        return matching[0] if matching else _Nothing()
    out: dict[str, Any] = {"n": len(matching)}
    for out_key, dotted in spec["mean"].items():
        values = [v for v in (_get(other, dotted) for other in matching) if v is not None]
        out[out_key] = sum(values) / len(values) if values else None
    return out


def rows(record: dict[str, Any], table: dict[str, Any], root: Path = RESULTS) -> list[dict[str, Any]]:
    """The table's rows: ``rows`` is a dotted path into the record (default ``runs``), or a list of them,
    each a path or ``{"path": ..., "set": {key: value}}`` (the value added to each of its rows), concatenated;
    ``where`` keeps the rows whose keys have the given values; ``join`` adds matching rows of other rows."""
    spec = table.get("rows", "runs")
    found: list[dict[str, Any]] = []
    for part in spec if isinstance(spec, list) else [spec]:
        part = {"path": part} if isinstance(part, str) else part
        found += [{**row, **part.get("set", {})} for row in _path(record, part["path"])]
    where = table.get("where", {})
    found = [row for row in found if all(row.get(k) == v for k, v in where.items())]
    for join_name, join in table.get("join", {}).items():
        other = load(join["record"], root) if join.get("record") else record
        source = _path(other, join["rows"])
        found = [{**row, join_name: _joined(row, join, source)} for row in found]
    return found


def _table(record: dict[str, Any], table_name: str, name: str) -> dict[str, Any]:
    try:
        table: dict[str, Any] = record["tables"][table_name]
    except KeyError:
        raise RecordError(f"results/{name}.json: no table {table_name!r}") from None
    return table


def cells(record: dict[str, Any], table_name: str, name: str = "", root: Path = RESULTS,
          markdown: bool = True) -> list[list[str]]:
    """The table's header and rows as text: Markdown cells (bold where a column says), or plain ones for a
    CSV file (no bold; a missing value is empty)."""
    table = _table(record, table_name, name)
    columns = table["columns"]
    out = [[col[0] for col in columns]]
    for row in rows(record, table, root):
        line = []
        for col in columns:
            opts = _options(col)
            try:
                cell = _CELLS.vformat(col[1], (), row)
            except (KeyError, IndexError, TypeError, ValueError) as exc:
                raise RecordError(f"results/{name}.json, table {table_name}: {col[1]!r}: {exc!r}") from exc
            if "per" in opts and _get(row, opts["per"]) == 0:
                cell = NONE  # a rate of a count of 0 is no figure
            if markdown and opts.get("bold") and _get(row, opts["bold"]) and cell != NONE:
                cell = f"**{cell}**"
            if not markdown and cell == NONE:
                cell = ""
            line.append(cell)
        out.append(line)
    return out


def render(record: dict[str, Any], table_name: str, name: str = "", caption: bool = True,
           root: Path = RESULTS) -> str:
    """The Markdown of one of the record's tables, with (``caption``) the line that says where its figures
    come from."""
    table = _table(record, table_name, name)
    header, *body = cells(record, table_name, name, root)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in body]
    if not caption:
        return "\n".join([*lines, ""])
    joined = [j["record"] for j in table.get("join", {}).values() if j.get("record")]
    if table.get("caption") == "records":
        named = " and ".join(f"`results/{n}.json`" for n in [name, *joined])
        line = f"*From {named}.*"
    else:
        line = provenance_line(record, name)
        for join in table.get("join", {}).values():
            if join.get("record"):  # its command is in its own record, and on the page that shows it
                other = load(join["record"], root)
                line = line[:-1] + (f"; {join.get('label', 'joined')}: code {code_version(other)}, "
                                    f"`results/{join['record']}.json`*")
    return "\n".join([*lines, "", line, ""])


def csv_text(record: dict[str, Any], table_name: str, name: str = "", root: Path = RESULTS) -> str:
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(cells(record, table_name, name, root, markdown=False))
    return out.getvalue()


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


def blocks(text: str) -> Iterator[re.Match[str]]:
    return BLOCK.finditer(text)


SECTION = re.compile(r"^## ", re.M)


def renderings(text: str, root: Path = RESULTS) -> list[tuple[re.Match[str], str]]:
    """Each results block of ``text`` with its rendering: the provenance line under the first table of
    each record in each section (``##``) only."""
    cache: dict[str, dict[str, Any]] = {}
    seen: set[tuple[int, str]] = set()
    out = []
    for match in blocks(text):
        name = match["name"]
        if name not in cache:
            cache[name] = load(name, root)
        section = len(SECTION.findall(text, 0, match.start()))
        first = (section, name) not in seen
        seen.add((section, name))
        out.append((match, render(cache[name], match["table"], name, caption=first, root=root)))
    return out


def fill(text: str, root: Path = RESULTS) -> str:
    """``text`` with every results block rendered afresh from its record."""
    parts, end = [], 0
    for match, body in renderings(text, root):
        parts += [text[end:match.start("body")], body]
        end = match.end("body")
    return "".join([*parts, text[end:]])


def pages(docs: Path = DOCS) -> list[Path]:
    """The pages that may hold results blocks: the site's, and the README beside ``docs/``."""
    readme = docs.parent / "README.md"
    return sorted(docs.rglob("*.md")) + ([readme] if readme.exists() else [])


def csv_tables(root: Path = RESULTS) -> list[tuple[str, str]]:
    """(record, table) of every table written as a CSV file."""
    return [(name, table) for name in names(root) for table, spec in load(name, root)["tables"].items()
            if spec.get("csv")]


def csv_path(name: str, table: str, docs: Path = DOCS) -> Path:
    return docs / CSV_FOLDER / f"{name}-{table}.csv"


def write_pages(docs: Path = DOCS, root: Path = RESULTS) -> list[Path]:
    """Render every block of every page, and every CSV table, from its record; the files that changed."""
    changed = []
    for page in pages(docs):
        text = page.read_text(encoding="utf-8")
        new = fill(text, root)
        if new != text:
            page.write_text(new, encoding="utf-8")
            changed.append(page)
    for name, table in csv_tables(root):
        path, text = csv_path(name, table, docs), csv_text(load(name, root), table, name, root)
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
            changed.append(path)
    return changed


def stale(docs: Path = DOCS, root: Path = RESULTS) -> list[str]:
    """``page: NAME TABLE`` for every block (or CSV file) whose text is not its record's rendering."""
    out = []
    for page in pages(docs):
        for match, body in renderings(page.read_text(encoding="utf-8"), root):
            if match["body"] != body:
                out.append(f"{page.relative_to(docs.parent)}: {match['name']} {match['table']}")
    for name, table in csv_tables(root):
        path = csv_path(name, table, docs)
        if not path.exists() or path.read_text(encoding="utf-8") != csv_text(load(name, root), table, name, root):
            out.append(f"{path.relative_to(docs.parent)}: {name} {table}")
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
    sub.add_parser("write", help="render every results block of docs/ and the README, and every CSV table, "
                                 "from its record")
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
