"""The documentation: the site builds with ``mkdocs build --strict``, and every command it shows parses.

A command in a page's code block that names a flag no parser has (or a subcommand that does not exist)
is how documentation drifts; each is parsed with the very parser the command uses.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
FENCE = re.compile(r"^```(\w*)\s*$")
SUBSTITUTION = re.compile(r"\$\((?:[^()]|\([^()]*\))*\)")


def shell_commands(path: Path) -> list[tuple[int, str]]:
    """(line, command) of every ``rbc`` / ``drive_server`` invocation in the page's shell code blocks."""
    found: list[tuple[int, str]] = []
    in_block, lang, pending, start = False, "", "", 0
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        fence = FENCE.match(line.strip())
        if fence:
            in_block, lang = (not in_block), fence.group(1)
            continue
        if not in_block or lang not in ("bash", "sh", "shell", "console"):
            continue
        text = line.strip().removeprefix("$ ")
        if pending:
            text, start = pending + " " + text, start
        else:
            start = n
        if text.endswith("\\"):
            pending = text[:-1].strip()
            continue
        pending = ""
        text = re.split(r"\s#\s|\s{2,}#", text)[0]  # a comment after the command
        text = re.split(r"\s>\s", text)[0]  # its output redirected to a file
        text = SUBSTITUTION.sub("--data DIR", text)  # $(for d in ...; do printf -- '--data %s ' ...; done)
        for part in re.split(r"\s(?:&&|\|\||;|\|)\s", text):
            part = part.strip().removesuffix(" &").strip()
            if part.startswith(("rbc ", "drive_server")) and "..." not in part:
                found.append((start, part))
    return found


def _parse(command: str) -> str | None:
    """None when the command parses; else what its parser said."""
    from drive_server.cli import build_parser
    from tools.cli import find_subcommand, load, subcommand_parser

    argv = shlex.split(command)
    if argv[0] == "drive_server":
        parser, rest = build_parser(), argv[1:]
    else:
        args = [a for a in argv[1:] if a not in ("-v", "--verbose")]
        if not args or args[0] in ("--version", "--help", "-h"):
            return None
        cmd, index = find_subcommand(args)
        if cmd is None:
            return f"no subcommand {args[0]!r}"
        parser, rest = subcommand_parser(cmd, load(cmd)), args[index + 1:]
    try:
        parser.parse_args(rest)
    except SystemExit as exc:
        return None if exc.code == 0 else "refused by its parser"
    return None


def test_the_pages_show_commands_at_all():
    assert sum(len(shell_commands(p)) for p in PAGES) > 40


def test_every_command_in_the_readme_and_the_site_parses(capsys):
    pytest.importorskip("torch")  # the train commands' modules
    pytest.importorskip("matplotlib")
    wrong = []
    for page in PAGES:
        for line, command in shell_commands(page):
            problem = _parse(command)
            if problem:
                wrong.append(f"{page.relative_to(REPO)}:{line}: {command} ({problem}: "
                             f"{capsys.readouterr().err.strip().splitlines()[-1:]})")
    assert wrong == []


def test_the_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("material")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    commands = (tmp_path / "site" / "reference" / "commands" / "index.html").read_text(encoding="utf-8")
    assert "usage: rbc train" in commands and "usage: drive_server" in commands  # generated from the parsers
    assert "TrainConfig" in (tmp_path / "site" / "reference" / "api" / "index.html").read_text(encoding="utf-8")
