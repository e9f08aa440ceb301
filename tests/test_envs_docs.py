"""Every Python example on the Gymnasium page (docs/python.md) runs verbatim and prints what the page shows.

A page's ``python`` blocks run in order, each with the blocks before it in the same section (a snippet may go on
from the example above it), in a fresh folder holding a link to the repository's ``models/``; a ``text`` block
right after one is what it must print, line for line.
"""

from __future__ import annotations

import contextlib
import io
import re
import textwrap
from pathlib import Path

import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "python.md"
BLOCK = re.compile(r"^```(\w*)\n(.*?)^```\n", re.S | re.M)
HEADING = re.compile(r"^#{2,3} (.+)$", re.M)
#: examples that need more than the gym extra
NEEDS = {"stable_baselines3": "the rl extra (pip install -e '.[rl]')", "torch": "the train extra",
         "imitation": "imitation (pip install -r requirements-imitation.txt && pip install --no-deps imitation==1.0.1)"}


def examples(page: Path = PAGE) -> list[tuple[str, str, str | None]]:
    """(section, code, the output shown after it or None) of every python block of the page, in order."""
    text = page.read_text(encoding="utf-8")
    found = []
    blocks = list(BLOCK.finditer(text))
    for i, block in enumerate(blocks):
        if block.group(1) != "python":
            continue
        headings = HEADING.findall(text[:block.start()])
        following = blocks[i + 1] if i + 1 < len(blocks) else None
        shown = None
        if following is not None and following.group(1) == "text" and not text[block.end():following.start()].strip():
            shown = following.group(2)
        found.append((headings[-1] if headings else "", block.group(2), shown))
    return found


EXAMPLES = examples()


def test_the_page_has_its_examples():
    sections = [section for section, _, _ in EXAMPLES]
    assert "A lap of the lake" in sections and "Domain randomisation" in sections
    assert all(shown is None or "\n" in shown for _, _, shown in EXAMPLES)


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(EXAMPLES)),
                         ids=[f"{i}-{s[:30]}" for i, (s, _, _) in enumerate(EXAMPLES)])
def test_every_example_runs_and_prints_what_the_page_shows(index, tmp_path, monkeypatch):
    section, code, shown = EXAMPLES[index]
    for module, extra in NEEDS.items():
        if f"{module}" in code or (module == "torch" and "models.training" in code):
            pytest.importorskip(module, reason=f"the example needs {extra}")
    with contextlib.suppress(ModuleNotFoundError):
        import torch

        torch.set_num_threads(1)  # the machine's other core is someone else's
    (tmp_path / "models").symlink_to(REPO / "models")
    monkeypatch.chdir(tmp_path)
    scope: dict = {"__name__": "__docs__"}
    before = [c for s, c, _ in EXAMPLES[:index] if s == section]  # what the snippet goes on from
    with contextlib.redirect_stdout(io.StringIO()):
        for earlier in before:
            exec(compile(textwrap.dedent(earlier), str(PAGE), "exec"), scope)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(textwrap.dedent(code), str(PAGE), "exec"), scope)
    if shown is not None:
        assert printed.getvalue().splitlines() == shown.splitlines()
