"""Fetching a public recording from its git repository, frames and log only (``rbc data fetch``).

A recording's repository often holds models, videos and other recordings too, so it is cloned without
blobs (``--filter=blob:none``) and only ``FOLDER/LOG`` (the manifest's ``log``, ``driving_log.csv`` unless
it names another) and ``FOLDER/IMG/`` are checked out at the manifest's commit (sparse checkout: the blobs
come in one batch). The result is ``OUT/NAME/`` with ``driving_log.csv`` (that log, only the manifest's
rows) and ``IMG/``; the marker file, written last, says the copy is complete, so an interrupted fetch is
redone and a complete one is skipped.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from protocol.datalog_writer import IMAGE_DIR, LOG_NAME
from protocol.rows import keep_rows, numbered_lines, read_lines
from tools.errors import CommandError
from tools.realdata.recordings import PublicRecording

DEFAULT_BASE_URL = "https://github.com"
MARKER = ".done"
PARTIAL = ".partial"  # OUT/.partial/NAME: the clone while a recording is fetched


@dataclass(frozen=True)
class Fetched:
    name: str
    folder: Path
    rows: int
    frames: int
    skipped: bool = False  # already complete

    def describe(self, rec: PublicRecording, base_url: str) -> str:
        if self.skipped:
            return f"{self.name}: already complete in {self.folder}, skipped"
        rows = f" (rows {rec.rows})" if rec.rows else ""
        log = rec.log if rec.log != LOG_NAME else ""
        return (f"{self.name}: {self.rows} rows{rows}, {self.frames} frames from {base_url.rstrip('/')}/"
                f"{rec.repository} at {rec.commit[:10]} /{rec.folder}{log} -> {self.folder}")


class _GitFailed(Exception):
    pass


def _git(*args: str, cwd: Path | None = None) -> str:
    env = {**os.environ, "GIT_TERMINAL_PROMPT": "0"}  # a missing GitHub repository asks for a password
    try:
        proc = subprocess.run(["git", *args], cwd=cwd, env=env, capture_output=True, text=True)
    except FileNotFoundError:
        raise CommandError("git is not installed", "install git to fetch recordings") from None
    if proc.returncode != 0:
        lines = [line.strip() for line in proc.stderr.splitlines() if line.strip()]
        raise _GitFailed(lines[-1] if lines else f"git {args[0]} exited with {proc.returncode}")
    return proc.stdout


def _checkout(rec: PublicRecording, url: str, clone: Path) -> None:
    """Clone ``url`` without blobs into ``clone`` and check out the recording's two paths at its commit."""
    _git("clone", "--quiet", "--no-checkout", "--filter=blob:none", url, str(clone))
    _git("config", "core.sparseCheckout", "true", cwd=clone)
    log, img = rec.paths()
    (clone / ".git" / "info").mkdir(parents=True, exist_ok=True)
    (clone / ".git" / "info" / "sparse-checkout").write_text(f"/{log}\n/{img}/\n", encoding="utf-8")
    try:
        _git("cat-file", "-e", f"{rec.commit}^{{commit}}", cwd=clone)
    except _GitFailed:  # not on any branch any more: ask for the commit itself
        _git("fetch", "--quiet", "--filter=blob:none", "origin", rec.commit, cwd=clone)
    _git("checkout", "--quiet", "--detach", rec.commit, cwd=clone)


def _prepare(dest: Path) -> None:
    """An empty ``dest``; a folder left by an interrupted fetch (only a log and IMG/) is cleared."""
    if dest.exists():
        if not dest.is_dir() or {p.name for p in dest.iterdir()} - {LOG_NAME, IMAGE_DIR}:
            raise CommandError(f"{dest} exists and is not an incomplete fetch of this recording",
                               "move it away, or fetch into another --out")
        shutil.rmtree(dest)
    dest.mkdir(parents=True)


def fetch(rec: PublicRecording, out: Path, base_url: str = DEFAULT_BASE_URL) -> Fetched:
    """``out/NAME/`` with the recording's log (its rows only) and frames; skipped if already complete."""
    dest = out / rec.name
    if (dest / MARKER).is_file():
        return Fetched(rec.name, dest, rows=0, frames=0, skipped=True)
    url = f"{base_url.rstrip('/')}/{rec.repository}"
    clone = out / PARTIAL / rec.name
    shutil.rmtree(clone, ignore_errors=True)
    clone.parent.mkdir(parents=True, exist_ok=True)
    try:
        try:
            _checkout(rec, url, clone)
        except _GitFailed as exc:
            raise CommandError(f"git could not fetch {url} at {rec.commit[:10]}: {exc}",
                               "check the network and that the repository still exists") from None
        log, img = (clone / p for p in rec.paths())
        if not log.is_file() or not img.is_dir():
            raise CommandError(f"{url} at {rec.commit[:10]} has no {rec.paths()[0]} and "
                               f"{rec.paths()[1]}/", "the manifest entry is wrong")
        _prepare(dest)
        log.replace(dest / LOG_NAME)
        img.replace(dest / IMAGE_DIR)
    finally:
        shutil.rmtree(clone, ignore_errors=True)
        if clone.parent.is_dir() and not any(clone.parent.iterdir()):
            clone.parent.rmdir()
    rows = (keep_rows(dest / LOG_NAME, rec.rows) if rec.rows
            else sum(1 for _, row, _ in numbered_lines(read_lines(dest / LOG_NAME)) if row > 0))
    frames = sum(1 for p in (dest / IMAGE_DIR).iterdir() if p.is_file())
    (dest / MARKER).write_text(f"{rec.repository} {rec.commit} /{rec.paths()[0]}\n", encoding="utf-8")
    return Fetched(rec.name, dest, rows, frames)
