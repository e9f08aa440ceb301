"""Figures written once: every results table is its record's rendering, and the pages hold to the site's rules.

The Results page's tables are rendered from ``results/*.json`` (the package ``tools/results/``); a table edited by hand,
or a record changed without its page (``python -m tools.results write``), fails here. The user pages (all but
the changelog and the experiments log) narrate no history, hold no table wider than 8 columns, and link
neither to the development checkout's ``../shared`` nor to an issue; no page links to or names a docs page
that does not exist. The Results page answers one question per section, each led by a table of at most 7
columns, says where a table was measured once per section and record, in one uniform line, and gives no
rate for a count of zero.
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
    for page in results.pages():
        text = page.read_text(encoding="utf-8")
        shown |= {(m["name"], m["table"]) for m in results.blocks(text)}
        shown |= {(name, table) for name, table in results.csv_tables()
                  if f"{results.CSV_FOLDER}/{name}-{table}.csv" in text}  # a CSV file a page links
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


def _record(rows, columns, **table):
    return {"title": "t", "provenance": "transcribed", "date": "2026-12-01", "code_version": "git abc1234-dirty",
            "machine": "2 cores (AMD EPYC), no GPU, Linux 6.1, load average 1.0 when measured",
            "source": "somewhere", "runs": [{"command": "rbc x", "output": {"rows": rows}}],
            "tables": {"t": {"rows": "runs.0.output.rows", "columns": columns, **table}}}


def test_rendering():
    record = _record([{"a": 1.234, "b": None, "ok": True, "p": "models/m.onnx"},
                      {"a": 2.0, "b": 3, "ok": False, "p": None}],
                     [["a", "{a:.1f}", "ok"], ["b", "{b}"], ["ok", "{ok!y}"], ["file", "{p!b}"]])
    text = results.render(record, "t", "x")
    assert text.splitlines()[:4] == ["| a | b | ok | file |", "|---|---|---|---|", "| **1.2** | – | yes | m.onnx |",
                                     "| 2.0 | 3 | no | – |"]
    # one short line: the command, the code version, the machine, the record; no date, no source, no -dirty
    assert text.splitlines()[-1] == ("*`rbc x` · code `abc1234` with uncommitted edits · 2 cores (AMD EPYC), no GPU"
                                     " · `results/x.json`, transcribed*")
    assert results.render(record, "t", "x", caption=False).splitlines()[-1] == "| 2.0 | 3 | no | – |"
    with pytest.raises(results.RecordError, match="'{c}'"):
        results.render({**record, "tables": {"t": {"rows": "runs.0.output.rows", "columns": [["c", "{c}"]]}}}, "t")


def test_a_rate_of_a_count_of_zero_prints_no_figure():
    record = _record([{"n": 0, "per": 82.5, "peer": {"n": 0, "per": 90.0}},
                      {"n": 2, "per": 41.3, "peer": {"n": 1, "per": None}}],
                     [["take-overs", "{n}"], ["s per take-over", "{per:.1f}", {"per": "n"}],
                      ["peer s per take-over", "{peer[per]}", {"per": "peer.n"}]])
    assert results.render(record, "t", "x").splitlines()[2:4] == ["| 0 | – | – |", "| 2 | 41.3 | – |"]
    assert results.csv_text(record, "t", "x").splitlines()[1:] == ["0,,", "2,41.3,"]


def test_a_join_adds_the_matching_row_or_the_mean_of_the_matching_rows(tmp_path):
    (tmp_path / "other.json").write_text(json.dumps(_record(
        [{"k": "a", "v": 1.0}, {"k": "a", "v": 2.0}, {"k": "b", "v": 5.0}], [["k", "{k}"]])), encoding="utf-8")
    record = _record([{"k": "a", "x": 1}, {"k": "c", "x": 2}], [["k", "{k}"], ["same", "{same[y]}"],
                                                                ["mean", "{other[v]:.1f} ({other[n]})"]],
                     join={"same": {"rows": "runs.0.output.more", "on": "k"},
                           "other": {"record": "other", "rows": "runs.0.output.rows", "on": "k",
                                     "mean": {"v": "v"}, "label": "the other"}})
    record["runs"][0]["output"]["more"] = [{"k": "a", "y": "yes"}]
    text = results.render(record, "t", "x", root=tmp_path)
    assert text.splitlines()[2:4] == ["| a | yes | 1.5 (2) |", "| c | – | – (0) |"]
    assert text.splitlines()[-1].endswith("; the other: code `abc1234` with uncommitted edits, `results/other.json`*")


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
    imitation = re.search(r"pip install -q --no-deps (imitation==[\d.]+)", "\n".join(ci)).group(1)
    assert f"pip install -r requirements-imitation.txt && pip install --no-deps {imitation}" in commands[1]
    assert len(readme.splitlines()) < 80
    # one small table, generated from the records, of how well the default model drives each track
    tables = _tables(readme)
    assert len(tables) == 1 and _columns(tables[0][0]) <= 5
    assert [(m["name"], m["table"]) for m in results.blocks(readme)] == [("crossval-unity", "readme")]
    assert "](docs/results.md#" in readme
    assert "Tried" not in readme and "share of time on the road" not in readme.lower()


def test_the_readme_and_install_say_the_same_of_torch():
    """The test command pins the CI machines' CPU build; both pages say what to install elsewhere."""
    cpu = "pip install torch --index-url https://download.pytorch.org/whl/cpu"
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    install = (DOCS / "install.md").read_text(encoding="utf-8")
    assert cpu in readme and cpu in install
    for text in (readme, install):
        assert "CI machines" in text and "replace `pip install torch==2.13.0` with" in " ".join(text.split())


RESULTS_PAGE = DOCS / "results.md"
#: The line under a table: ``*`command` · code `abc1234`[ with uncommitted edits] · machine · `results/NAME.json`*``.
PROVENANCE = re.compile(r"^\*`[^`]+` · code `[0-9a-f]{7}`(?: with uncommitted edits)? · [^·`]+ · "
                        r"`results/(?P<name>[\w-]+)\.json`(?:, transcribed)?(?:; [^*]+)?\*$")


def _sections(text: str) -> list[str]:
    return re.split(r"^## ", text, flags=re.M)[1:]


def test_each_section_of_the_results_page_is_led_by_one_table_of_at_most_7_columns():
    text = RESULTS_PAGE.read_text(encoding="utf-8")
    sections = _sections(text)
    assert len(sections) >= 5
    for section in sections:
        lead = re.split(r"^### |^<details", section, flags=re.M)[0]
        tables = _tables(lead)
        assert tables, f"section {section.splitlines()[0]!r} is led by no table"
    for table in _tables(text):
        assert _columns(table[0]) <= 7, table[0]
        headers = [cell.strip() for cell in re.split(r"(?<!\\)\|", table[0])[1:-1]]
        assert all(len(header) <= 32 for header in headers), table[0]  # short headers: the column fits 1280 px


@pytest.mark.parametrize("page", [REPO / "README.md", *sorted(DOCS.rglob("*.md"))], ids=lambda p: p.name)
def test_provenance_is_one_uniform_line_once_per_section_and_record(page):
    text = page.read_text(encoding="utf-8")
    for number, section in enumerate(re.split(r"^## ", text, flags=re.M)):
        lines = [line for line in section.splitlines() if line.startswith("*`") and "`results/" in line]
        names = []
        for line in lines:
            match = PROVENANCE.match(line)
            assert match, line
            names.append(match["name"])
        assert len(names) == len(set(names)), f"section {number} names a record twice: {names}"
    if page.name not in HISTORY:
        assert "transcribed from" not in text and not re.search(r"\bMeasured 20\d\d-", text)


def test_no_table_gives_a_rate_for_a_count_of_zero():
    """A "per take-over" column next to a "take-overs" one prints no figure where the count is 0, and every
    record's column of seconds per take-over says which count it is a rate of."""
    checked = 0
    for page in results.pages():
        for table in _tables(page.read_text(encoding="utf-8")):
            header = [cell.strip() for cell in table[0].strip("|").split("|")]
            for rate, cell in enumerate(header):
                if "per take-over" not in cell:
                    continue
                counted = cell.replace("s per take-over", "take-overs").strip()
                if counted not in header:
                    continue
                count = header.index(counted)
                for line in table[2:]:
                    cells = [c.strip() for c in line.strip("|").split("|")]
                    if cells[count] == "0":
                        checked += 1
                        assert cells[rate] == "–", line
    assert checked >= 1
    for name in results.names():
        for table, spec in results.load(name)["tables"].items():
            for column in spec["columns"]:
                if "seconds_per_takeover" in column[1]:
                    assert "per" in results.column_options(column), (name, table, column)


def _named_pages(page: Path, text: str) -> list[str]:
    """The docs pages (and other files of the site) a page links to or names that do not exist."""
    missing = []
    text_links = re.sub(r"```.*?```", "", text, flags=re.S)
    base = DOCS if page.name != "README.md" else REPO
    for target in re.findall(r"\]\(([^)\s#]+)(?:#[^)\s]*)?\)", text_links):
        if re.match(r"[a-z]+:", target):
            continue
        if not (page.parent / target).exists():
            missing.append(target)
    for named in re.findall(r"\bdocs/[\w/.-]+\.md\b", text):
        if not (REPO / named).exists():
            missing.append(named)
    del base
    return missing


@pytest.mark.parametrize("page", [REPO / "README.md", *sorted(DOCS.rglob("*.md"))], ids=lambda p: p.name)
def test_no_page_links_to_or_names_a_docs_page_that_does_not_exist(page):
    text = page.read_text(encoding="utf-8")
    if page.name in HISTORY:  # history may name a page that was, but links only to what is
        text = re.sub(r"\bdocs/[\w/.-]+\.md\b", "", text)
    assert _named_pages(page, text) == []


def test_a_dangling_page_name_is_found():
    page = DOCS / "results.md"
    assert _named_pages(page, "see [it](robustness.md#table-9) and docs/hostile.md") == [
        "robustness.md", "docs/hostile.md"]
    assert _named_pages(page, "see [it](paper.md#x), [csv](data/crossval-unity-recordings.csv), docs/paper.md") == []


def test_install_names_every_extra():
    import tomllib

    extras = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    install = (DOCS / "install.md").read_text(encoding="utf-8")
    assert [e for e in extras if f"| `{e}` |" not in install] == []

