"""The pages agree with each other, with the code and with the glossary (#55).

One name for each thing, the glossary's: *degree of autonomy* (eta only in formulas and JSON keys),
*take-over* (the paper's *intervention* only where the glossary says so), *behavioral*, *r9* and
*r to intent*; what a command covers and how long it takes said the same way on every page; the project
installed one way; the Unity guide saying where each side may run.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.test_docs_layout import user_pages

REPO = Path(__file__).resolve().parents[1]
#: Pages whose wording is being rewritten elsewhere (none now). The last test fails while a page listed here already
#: passes, so the list only shrinks.
OTHERS_RENAMING: set[str] = set()
#: Words the glossary replaced, and the one it uses (outside code, where JSON keys and formulas keep eta).
RETIRED = {
    r"\bbehavioural\b": "behavioral",
    r"\binterventions?\b": "take-over",
    r"\b(?:eta|η)\b": "degree of autonomy",
    r"\bceiling\b": "r9",
    r"\br to (?:the )?mean\b": "r to intent",
}
#: Where a retired word stands on purpose: the glossary saying what the paper calls a take-over and what eta is.
ALLOWED = {("docs/glossary.md", "(The paper says *intervention*.)"),
           ("docs/glossary.md", "## Degree of autonomy (eta)")}


def prose(page: str) -> list[str]:
    """The page's lines outside code blocks, inline code, link targets, HTML and generated results tables."""
    text = (REPO / page).read_text(encoding="utf-8")
    text = re.sub(r"<!-- results .*?<!-- /results -->", "", text, flags=re.S)  # a record's table (tools/results)
    text = re.sub(r"(?ms)^(\s*)(```|~~~).*?^\1\2\s*$", "", text)
    lines = []
    for line in text.splitlines():
        if any(page == p and allowed in line for p, allowed in ALLOWED):
            continue
        line = re.sub(r"`[^`]*`", "", line)
        line = re.sub(r"\]\([^)]*\)", "]", line)  # link targets: file names, anchors
        line = re.sub(r"<[^>]+>", "", line)
        lines.append(line)
    return lines


def retired_words(page: str) -> list[str]:
    found = []
    for line in prose(page):
        hits = sorted((m.start(), m.group(0), better) for pattern, better in RETIRED.items()
                      for m in re.finditer(pattern, line, flags=re.I))
        found += [f"{page}: {word!r} (say {better!r}): {line.strip()[:90]}" for _, word, better in hits]
    return found


def test_the_check_finds_a_retired_word_and_spares_code():
    page = REPO / "tests" / "data" / "_words.md"
    page.write_text("The eta of the lap, two interventions, `eta` and `interventions` in JSON.\n"
                    "```text\nη = 100.0 %\n```\nBehavioural cloning, a ceiling, r to the mean.\n", encoding="utf-8")
    try:
        found = [f.split(": ")[1] for f in retired_words(page.relative_to(REPO).as_posix())]
    finally:
        page.unlink()
    assert found == ["'eta' (say 'degree of autonomy')", "'interventions' (say 'take-over')",
                     "'Behavioural' (say 'behavioral')", "'ceiling' (say 'r9')", "'r to the mean' (say 'r to intent')"]


@pytest.mark.parametrize("page", [p for p in user_pages() if p not in OTHERS_RENAMING])
def test_a_page_uses_the_glossarys_names(page):
    found = retired_words(page)
    assert not found, "\n".join(found)


def table_header_words(record: Path) -> list[str]:
    """Retired words in the column headers of a results record's tables (the pages' generated tables; their cells
    keep the paper's notation, e.g. Table 9's η = ...)."""
    import json

    found = []
    for name, table in (json.loads(record.read_text(encoding="utf-8")).get("tables") or {}).items():
        for column in table.get("columns", []):
            header = str(column[0])
            hits = [better for pattern, better in RETIRED.items() if re.search(pattern, header, flags=re.I)]
            found += [f"{record.name} {name}: {header!r} (say {better!r})" for better in hits]
    return found


def test_the_generated_tables_use_the_glossarys_names_too():
    """Was: Results' tables said "ceiling" and "r to mean", DAgger's "lake η", where the prose said r9, r to intent
    and degree of autonomy (the prose check leaves the generated tables out)."""
    found = [hit for record in sorted((REPO / "results").glob("*.json")) for hit in table_header_words(record)]
    assert not found, "\n".join(found)


def test_the_header_check_finds_a_retired_header(tmp_path):
    record = tmp_path / "x.json"
    record.write_text('{"tables": {"t": {"columns": [["ceiling", "{a}"], ["r9", "{b}"], ["lake η", "{c}"]]}}}',
                      encoding="utf-8")
    assert table_header_words(record) == ["x.json t: 'ceiling' (say 'r9')",
                                          "x.json t: 'lake η' (say 'degree of autonomy')"]


def test_the_pages_being_renamed_elsewhere_still_need_it():
    fixed = [page for page in sorted(OTHERS_RENAMING) if not retired_words(page)]
    assert fixed == [], f"remove {fixed} from OTHERS_RENAMING in {Path(__file__).name}: they pass"


def test_the_crossval_and_drive_log_pages_say_every_track_and_one_duration(capsys):
    """Was: Evaluate called both lake-only, and the closed loop took "minutes", "~10" or "about 20" by page."""
    from tools.cli import main
    from tools.realdata.crossval import CLOSED_LOOP_TRACKS
    from tools.realdata.recordings import TRACKS

    assert set(CLOSED_LOOP_TRACKS) == set(TRACKS)
    evaluate = (REPO / "docs" / "evaluate.md").read_text(encoding="utf-8")
    rows = [line for line in evaluate.splitlines() if re.match(r"\| .* \| `rbc (drive-log|data crossval)` \|", line)]
    assert len(rows) == 2 and not any(re.search(r"\((?:lake|jungle|mountain)\)", row) for row in rows), rows
    assert not re.search(r"closed loop on the (?:lake|jungle|mountain) recordings", evaluate)
    with pytest.raises(SystemExit):
        main(["data", "crossval", "--help"])
    crossval_help = capsys.readouterr().out
    said = {}
    for name, text in (("evaluate.md", evaluate), ("crossval --help", crossval_help),
                       ("unity-model.md", (REPO / "docs" / "unity-model.md").read_text(encoding="utf-8"))):
        flat = re.sub(r"\s+", " ", text)
        said[name] = {m.group(1) for m in re.finditer(r"(?:about|~) ?(\d+)", flat)
                      if re.search(r"closed[ -]loop", flat[max(0, m.start() - 100):m.end() + 100])}
    assert all(said.values()) and set().union(*said.values()) == {"20"}, said


def test_the_project_is_installed_one_way():
    """Was: Scale out installed robust-behavioral-cloning by name, which Install never offers."""
    for page in user_pages():
        text = (REPO / page).read_text(encoding="utf-8")
        assert not re.search(r"pip\s+install\s+[\"']?robust-behavioral-cloning", text), page


def test_the_unity_guide_says_where_each_side_runs_and_how_they_meet():
    """Was: the box said the simulator may run elsewhere; only the troubleshooting said it connects to localhost."""
    page = (REPO / "docs" / "unity.md").read_text(encoding="utf-8")
    box = page.split('!!! note "You need"', 1)[1].split("\n## ", 1)[0]
    for needed in ("4567", "localhost:4567", "ssh -L 4567:localhost:4567 SERVER", "Linux", "macOS", "Windows",
                   "untested", "CI"):
        assert needed in box, needed
