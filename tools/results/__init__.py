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

The package by job: :mod:`~tools.results.records` reads and checks a record, :mod:`~tools.results.tables`
makes a table's cells and Markdown, :mod:`~tools.results.pages` writes and checks the pages' blocks and CSV files,
:mod:`~tools.results.measuring` runs a record's commands again; ``__main__`` is the command. Everything is
importable from here (``from tools import results; results.render(...)``).
"""

from tools.results.measuring import LINKED, machine, measure
from tools.results.pages import (
    BLOCK,
    CSV_FOLDER,
    SECTION,
    blocks,
    csv_path,
    csv_tables,
    fill,
    pages,
    renderings,
    stale,
    write_pages,
)
from tools.results.records import (
    DOCS,
    PROVENANCES,
    REPO,
    REQUIRED,
    RESULTS,
    RecordError,
    code_version,
    load,
    machine_short,
    names,
    provenance_line,
)
from tools.results.tables import NONE, cells, column_options, csv_text, render, rows

__all__ = ["BLOCK", "CSV_FOLDER", "DOCS", "LINKED", "NONE", "PROVENANCES", "REPO", "REQUIRED", "RESULTS", "SECTION",
           "RecordError", "blocks", "cells", "code_version", "column_options", "csv_path", "csv_tables", "csv_text",
           "fill", "load", "machine", "machine_short", "measure", "names", "pages", "provenance_line", "render",
           "renderings", "rows", "stale", "write_pages"]
