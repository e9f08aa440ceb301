"""The error boundary of every ``rbc`` command: what a user did wrong becomes one line and a hint.

Bad data, a bad track, a bad model, a missing file, a permission problem, a full disk or a missing
extra is the user's input, not a bug: it gets ``rbc COMMAND: error: ...`` (and a hint) on stderr
and exit code 2, never a traceback (``rbc -v`` shows the traceback). Ours say so by deriving from
:class:`protocol.errors.UserError` (whose hint they carry); the file system's and the network's are
OSErrors. Anything else, a bare ValueError included, is a bug and keeps its traceback.
"""

from __future__ import annotations

import errno
import shutil
from collections.abc import Iterable
from pathlib import Path

from protocol.errors import UserError


class CommandError(UserError):
    """Raised by a command for a problem it has already described in words (message, hint)."""


def _hint_for(exc: BaseException) -> str:
    """The exception's own hint; for the file system's and the network's errors, one by their errno."""
    if isinstance(exc, UserError):
        return exc.hint
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
    """Input problems (ours: :class:`UserError`; the file system's and network's: OSError, TimeoutError,
    ConnectionError) as opposed to bugs. A bare ValueError is a bug: numpy's say nothing a user could act on."""
    return isinstance(exc, UserError | OSError)


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
