"""A record's table as cells: its rows (with joins and filters), each column's template, bold and "–".

The table is a function of the record alone (and of the records it joins), so the same cells serve the page's
Markdown (:func:`render`) and the CSV file a page links (:func:`csv_text`).
"""

from __future__ import annotations

import csv
import io
import string
from pathlib import Path
from typing import Any

from tools.results.records import RESULTS, RecordError, code_version, load, provenance_line

NONE = "–"


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


def column_options(column: list[Any]) -> dict[str, Any]:
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
            opts = column_options(col)
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
