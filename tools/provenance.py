"""Code version and file hashes recorded in every results file."""

from __future__ import annotations

import hashlib
import subprocess
from importlib import metadata
from pathlib import Path


def code_version() -> str:
    """``git describe`` of the checkout when there is one (with -dirty), else the package version."""
    root = Path(__file__).resolve().parents[1]
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty", "--tags"], cwd=root, capture_output=True,
                             text=True, timeout=5, check=True)
        return f"git:{out.stdout.strip()}"
    except (OSError, subprocess.SubprocessError):
        pass
    try:
        return f"pkg:{metadata.version('robust-behavioral-cloning')}"
    except metadata.PackageNotFoundError:
        return "unknown"


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()
