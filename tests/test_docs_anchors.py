"""Every link to a section of a page (``page.md#anchor``) in the docs, the README and the model cards lands on a
heading of that page (slugged as Python-Markdown's ``toc`` does, the docs site's) or an ``<a id>`` in it; a page
whose sections are generated when the site is built (the command reference) is taken on trust."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = sorted([REPO / "README.md", *(REPO / "docs").rglob("*.md"), *(REPO / "models" / "pretrained").glob("*.md")])
LINK = re.compile(r"\]\(([^)#\s]*\.md)#([^)\s]+)\)")


def _slug(heading: str) -> str:
    """Python-Markdown toc's default slugify: drop all but word characters, spaces and hyphens; lower; hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link in a heading: its text
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    found = {_slug(m.group(1)) for m in re.finditer(r"^#{1,6} (.+?)\s*$", text, flags=re.M)}
    return found | set(re.findall(r'<a id="([^"]+)"', text))


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_section_link_lands_on_a_heading(page):
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    broken = []
    for target, anchor in LINK.findall(text):
        path = (page.parent / target).resolve()
        generated = path.is_file() and "<!-- generated:" in path.read_text(encoding="utf-8")  # sections at build time
        if path.is_file() and not generated and anchor not in _anchors(path):
            broken.append(f"{target}#{anchor}")
    assert broken == []
