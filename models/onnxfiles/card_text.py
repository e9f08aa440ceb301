"""How a model card words things: prose wrapped to the card's width, shell commands quoted and wrapped between
flags, paths as a user types them, counts in words."""

from __future__ import annotations

import shlex
import textwrap
from pathlib import Path

#: Width of the card's lines of prose and of its wrapped commands.
WIDTH = 110


def block(heading: str, commands: list[str], text: str, head: str = "") -> str:
    parts = [heading, *([wrap(head)] if head else []), "```bash\n" + "\n".join(commands) + "\n```"]
    return "\n\n".join([*parts, *([wrap(text)] if text else [])])


def command(words: list[str]) -> str:
    """A shell command, quoted, wrapped onto continuation lines between a flag and the one before."""
    groups: list[str] = []
    for word in map(shlex.quote, words):
        if groups and not word.startswith("-"):
            groups[-1] += f" {word}"
        else:
            groups.append(word)
    lines = [groups[0]]
    for group in groups[1:]:
        if len(lines[-1]) + len(group) + 3 > WIDTH:
            lines.append("   ")
        lines[-1] += f" {group}"
    return " \\\n".join(lines)


def wrap(text: str, indent: str = "") -> str:
    return textwrap.fill(text, WIDTH, subsequent_indent=indent, break_long_words=False, break_on_hyphens=False)


def shown(path: str) -> str:
    """A folder the run recorded (absolute), relative to the working directory where it lies below it."""
    p, here = Path(path), Path.cwd()
    return p.relative_to(here).as_posix() if p.is_absolute() and p.is_relative_to(here) else p.as_posix()


def quoted(path: str | Path) -> str:
    return shlex.quote(Path(path).as_posix())


def count(n: int, word: str) -> str:
    return f"{'one' if n == 1 else n} {word}{'' if n == 1 else 's'}"
