"""Figures written once: every results table is its record's rendering, and the pages hold to the site's rules.

The Results page's tables are rendered from ``results/*.json`` (``tools/results.py``); a table edited by hand,
or a record changed without its page (``python -m tools.results write``), fails here. The user pages (all but
the changelog and the experiments log) narrate no history, hold no table wider than 8 columns, and link
neither to the development checkout's ``../shared`` nor to an issue.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from tools import results

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
HISTORY = {"changelog.md", "experiments.md"}
USER_PAGES = sorted(p for p in DOCS.rglob("*.md") if p.name not in HISTORY)
#: Words of a page that tells what happened rather than what is.
HISTORY_WORDS = re.compile(
    r"\b(was bundled|bundled before|bundled until|until (?:December|November|now)|before (?:December|November|the "
    r"mirror|recipes)|the old (?:finder|default|model)|it replaced|first version|handed back at once|as before|"
    r"no longer|used to be|since December|\(was [-\d])", re.I)


def _tables(text: str) -> list[list[str]]:
    """The Markdown tables of a text: their lines."""
    found, current = [], []
    for line in text.splitlines():
        if line.startswith("|"):
            current.append(line)
        elif current:
            found.append(current)
            current = []
    return found + ([current] if current else [])


def _columns(line: str) -> int:
    return len(re.split(r"(?<!\\)\|", line.strip())) - 2


def test_every_record_is_complete():
    names = results.names()
    assert len(names) >= 15
    for name in names:
        record = results.load(name)
        assert record["date"] and record["code_version"] and record["machine"], name
        assert record["runs"] and all(run.get("command") for run in record["runs"]), name
        if record["provenance"] == "measured":
            assert all(run.get("reads") and run.get("output") for run in record["runs"]), name
        for table in record["tables"]:
            assert results.render(record, table, name).count("\n|") >= 2, (name, table)


def test_every_results_table_on_the_pages_is_its_records_rendering():
    assert results.stale() == []


def test_every_record_is_shown_and_every_table_of_the_results_page_comes_from_one():
    shown = set()
    for page in DOCS.rglob("*.md"):
        shown |= {(m["name"], m["table"]) for m in results.blocks(page.read_text(encoding="utf-8"))}
    wanted = {(name, table) for name in results.names() for table in results.load(name)["tables"]}
    assert wanted == shown
    page = (DOCS / "results.md").read_text(encoding="utf-8")
    outside = results.BLOCK.sub("", page)
    assert _tables(outside) == [], "a table on the Results page that no record renders"


def test_a_hand_edited_figure_fails(tmp_path):
    docs = tmp_path / "docs"
    shutil.copytree(DOCS, docs)
    page = docs / "results.md"
    text = page.read_text(encoding="utf-8")
    edited = re.sub(r"(\| `unity.onnx` \| lake \| )[\d.]+ \|", r"\g<1>12.3 |", text, count=1)  # whatever it was
    assert edited != text
    page.write_text(edited, encoding="utf-8")
    assert results.stale(docs) == ["docs/results.md: headless-laps laps"]
    results.write_pages(docs)
    assert page.read_text(encoding="utf-8") == text


def test_a_changed_record_fails_until_its_page_is_written(tmp_path):
    root = tmp_path / "results"
    shutil.copytree(REPO / "results", root)
    record = json.loads((root / "demo.json").read_text(encoding="utf-8"))
    record["runs"][0]["output"]["laps"][0]["eta"] = 93.1
    (root / "demo.json").write_text(json.dumps(record), encoding="utf-8")
    assert results.stale(DOCS, root) == ["docs/results.md: demo lap"]


def test_rendering():
    record = {"title": "t", "provenance": "transcribed", "date": "2026-12-01", "code_version": "git abc",
              "machine": "m", "source": "somewhere", "runs": [{"command": "rbc x", "output": {"rows": [
                  {"a": 1.234, "b": None, "ok": True}, {"a": 2.0, "b": 3, "ok": False}]}}],
              "tables": {"t": {"rows": "runs.0.output.rows",
                               "columns": [["a", "{a:.1f}", "ok"], ["b", "{b}"], ["ok", "{ok!y}"]]}}}
    text = results.render(record, "t", "x")
    assert text.splitlines()[:4] == ["| a | b | ok |", "|---|---|---|", "| **1.2** | – | yes |", "| 2.0 | 3 | no |"]
    assert "transcribed from somewhere" in text and "`results/x.json`" in text
    with pytest.raises(results.RecordError, match="'{c}'"):
        results.render({**record, "tables": {"t": {"rows": "runs.0.output.rows", "columns": [["c", "{c}"]]}}}, "t")


def test_the_cross_validation_summary_is_its_recordings():
    """The transcribed per-track figures agree with the per-recording ones they summarise."""
    output = results.load("crossval-unity")["runs"][0]["output"]
    for who in ("folds", "peer"):
        for track in output[who]["tracks"]:
            mine = [r for r in output[who]["recordings"] if r["track"] == track["track"]]
            assert track["recordings"] == len(mine)
            assert abs(track["mean_r"] - sum(r["pearson_r"] for r in mine) / len(mine)) < 0.006
            assert track["beats_zero"] == sum(r["mse"] < r["zero_mse"] for r in mine)
            driven = [r for r in mine if r["eta"] is not None]
            if driven:
                assert abs(track["mean_eta"] - sum(r["eta"] for r in driven) / len(driven)) < 0.06
                assert track["worst_eta"] == min(r["eta"] for r in driven)
                assert track["takeovers"] == sum(r["interventions"] for r in driven)
                assert track["at_least_95"] == sum(r["eta"] >= 95 for r in driven)


@pytest.mark.parametrize("page", USER_PAGES, ids=lambda p: str(p.relative_to(DOCS)))
def test_a_user_page_holds_no_table_wider_than_8_columns(page):
    text = page.read_text(encoding="utf-8")
    wide = [t[0] for t in _tables(text) if _columns(t[0]) > 8]
    assert wide == []


@pytest.mark.parametrize("page", [REPO / "README.md", *USER_PAGES], ids=lambda p: p.name)
def test_a_user_page_narrates_no_history(page):
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    assert HISTORY_WORDS.findall(text) == []


@pytest.mark.parametrize("page", [REPO / "README.md", *sorted(DOCS.rglob("*.md"))], ids=lambda p: p.name)
def test_no_page_links_to_the_development_checkout_or_to_an_issue(page):
    text = page.read_text(encoding="utf-8")
    assert "../shared" not in text and "/issues/" not in text and "/pull/" not in text
    assert re.findall(r"(?<![\w/&`])#\d{1,4}\b", text) == []
    assert "the issue" not in text.lower()


def test_the_readme_is_a_front_door():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    commands = re.findall(r"```bash\n(.*?)\n```", readme, re.S)
    assert commands[0].endswith("pip install -e . && rbc demo")
    assert commands[1].endswith("&& python -m pytest -q") and ci[-1] == "python -m pytest -q"
    extras = re.search(r'pip install -q -e "\.\[([\w,]+)\]"', "\n".join(ci)).group(1)
    assert f'pip install -e ".[{extras}]"' in commands[1]
    torch = re.search(r"pip install -q (torch==[\d.]+)", "\n".join(ci)).group(1)
    assert f"pip install {torch}" in commands[1]
    assert len(readme.splitlines()) < 80 and _tables(readme) == []


def test_install_names_every_extra():
    import tomllib

    extras = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    install = (DOCS / "install.md").read_text(encoding="utf-8")
    assert [e for e in extras if f"| `{e}` |" not in install] == []
