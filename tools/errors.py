"""The error boundary of every ``rbc`` command: what a user did wrong becomes one line and a hint.

Bad data, a bad track, a bad model, a missing file, a permission problem, a full disk or a missing
extra is the user's input, not a bug: it gets ``rbc COMMAND: error: ...`` (and a hint) on stderr
and exit code 2, never a traceback (``rbc -v`` shows the traceback). Anything else is a bug and
keeps its traceback.
"""

from __future__ import annotations

import errno
import shutil
from collections.abc import Iterable
from pathlib import Path

#: Packages of ours whose exceptions describe bad input (their messages are written for users).
OUR_PACKAGES = ("protocol", "drive_server", "models", "tools")


class CommandError(Exception):
    """Raised by a command for a problem it has already described in words (message, hint)."""

    def __init__(self, message: str, hint: str = "") -> None:
        super().__init__(message)
        self.hint = hint


def _hint_for(exc: BaseException) -> str:
    name = type(exc).__name__
    if isinstance(exc, CommandError):
        return exc.hint
    if name == "DataLogError":
        return "give a recording folder with driving_log.csv and IMG/, as rbc collect or the simulator writes"
    if name == "TrackError":
        return "the track file format is in docs/formats.md (File formats: Track file)"
    if name in ("ModelError", "ContractError", "ExportError"):
        return "pass an .onnx model exported by rbc train, or a bundled one from models/pretrained/"
    if name in ("RunDirError", "OutputDirError"):
        return ""  # their messages say what to do
    if isinstance(exc, OSError):
        if exc.errno == errno.ENOSPC:
            return "free some disk space, or write to another disk"
        if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
            return "choose a folder you can write to"
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            return "check the path"
        if isinstance(exc, ConnectionError | TimeoutError):
            return "is drive_server running at that address?"
    return ""


def is_user_error(exc: BaseException) -> bool:
    """Input problems (ours, file system, network, bad values) as opposed to bugs."""
    if isinstance(exc, CommandError | OSError | ValueError | TimeoutError):
        return True
    return type(exc).__module__.split(".")[0] in OUR_PACKAGES  # our error types carry messages for users


def one_line(command: str, exc: BaseException) -> str:
    """``rbc COMMAND: error: message (hint)`` on one line."""
    if isinstance(exc, OSError) and exc.strerror and not isinstance(exc, ConnectionError | TimeoutError):
        where = f"{exc.filename}: " if exc.filename else ""
        message = f"{where}{exc.strerror.lower()}"
    else:
        message = str(exc) or type(exc).__name__
    message = " ".join(message.split())  # one line, whatever the exception held
    hint = _hint_for(exc)
    return f"rbc {command}: error: {message}" + (f" (hint: {hint})" if hint else "")


def snapshot(paths: Iterable[Path | None]) -> list[Path]:
    """The given output paths that do not exist yet (to remove them if the command fails)."""
    return [Path(p) for p in paths if p is not None and not Path(p).exists()]


def remove_new_empty_outputs(created: Iterable[Path]) -> None:
    """Remove outputs a failed command created but left empty (folders with no file in them, empty files)."""
    for path in created:
        if path.is_dir() and not any(p.is_file() and p.stat().st_size for p in path.rglob("*")):
            shutil.rmtree(path, ignore_errors=True)
        elif path.is_file() and path.stat().st_size == 0:
            path.unlink(missing_ok=True)
