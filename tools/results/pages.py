"""The pages that show records: every ``<!-- results NAME TABLE -->`` block and CSV table, rendered or checked.

``write`` (:func:`write_pages`) puts each block's rendering into its page and each CSV table into ``docs/data/``;
``check`` (:func:`stale`) lists the ones that are not their record's rendering, so a figure edited by hand or a
record changed without its page is found.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from tools.results.records import DOCS, RESULTS, load, names
from tools.results.tables import csv_text, render

#: Where ``write`` puts the tables a page offers as CSV files (``"csv": true``).
CSV_FOLDER = "data"
#: ``<!-- results NAME TABLE -->`` ... ``<!-- /results -->``
BLOCK = re.compile(r"(<!-- results (?P<name>[\w-]+) (?P<table>[\w-]+) -->\n)(?P<body>.*?)(<!-- /results -->)", re.S)
#: A page's section: the provenance line stands under a record's first table in each.
SECTION = re.compile(r"^## ", re.M)


def blocks(text: str) -> Iterator[re.Match[str]]:
    return BLOCK.finditer(text)


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
