"""Run records for every package: atomic file writes, the code version and file hashes.

Why here: deployment code (the server's stats) writes results too, and must not import the
training package, so the one writer lives at the bottom (protocol) that every package may import
(stdlib only).
Every file is written to a temporary name and renamed, so a crash or Ctrl-C never leaves half a
file behind, and every file gets the same mode (0666 minus the umask, like ``open``).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Any

from protocol.errors import BadValue

PACKAGE = "robust-behavioral-cloning"


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; it replaces ``path`` only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes(path: Path, write: Callable[[Path], object]) -> None:
    """Atomically create ``path`` with ``write(tmp_path)`` (for writers that want a file name)."""
    with atomic_path(path) as tmp:
        write(tmp)


def write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def json_default(value: object) -> object:
    """What ``json.dumps`` cannot write itself: a numpy number as the number it holds (a numpy count summed into a
    figure would otherwise be written as the string "22"), anything else (a path, a date) as its text."""
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "shape", None) == ():
        return item()
    return str(value)


def write_json(path: Path, data: object, sort_keys: bool = False) -> None:
    write_text(path, json.dumps(data, indent=2, sort_keys=sort_keys, default=json_default) + "\n")


def read_json(path: Path) -> Any:  # json.loads's own type: the caller knows the document's shape
    """A JSON file a run, an evaluation or a user wrote; one that is not JSON (cut short, or not text) is the user's
    to fix: a :class:`~protocol.errors.BadValue` naming the file, not a bug's traceback."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
        raise BadValue(f"{path}: not valid JSON ({exc})") from None


def code_version() -> str:
    """``git describe`` of this checkout when available, else the installed package version."""
    root = Path(__file__).resolve().parents[1]
    if (root / ".git").exists():
        try:
            out = subprocess.run(["git", "describe", "--always", "--dirty", "--tags"], cwd=root, capture_output=True,
                                 text=True, timeout=10, check=True)
            return f"git {out.stdout.strip()}"
        except (OSError, subprocess.SubprocessError):
            pass
    try:
        return f"{PACKAGE} {metadata.version(PACKAGE)}"
    except metadata.PackageNotFoundError:
        return "unknown"


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()
