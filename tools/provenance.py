"""Code version and file hashes recorded in every results file."""

from __future__ import annotations

import hashlib
from pathlib import Path

from models.runfiles import code_version  # one definition, shared with training runs

__all__ = ["code_version", "file_sha256"]


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()
