"""Appending whole records to a file: a record lands whole or not at all.

A full disk (ENOSPC) can take part of a write; the file is then cut back to its size before the write
and the error goes on, so a log or journal never ends in half a record that a later append would glue
onto. Stdlib only (the driving-log writer, the evaluation journal and the recorder share it).
"""

from __future__ import annotations

import os


def append_whole(fd: int, data: bytes) -> None:
    """Append ``data`` to the file open as ``fd`` (``O_APPEND``): all of it, or none of it and raise."""
    size = os.fstat(fd).st_size
    try:
        done = os.write(fd, data)
        while done < len(data):  # a short write: the rest raises if the disk is full
            done += os.write(fd, data[done:])
    except OSError:
        os.ftruncate(fd, size)
        raise


def append_record(path: os.PathLike[str] | str, data: bytes) -> None:
    """Open ``path`` for appending, :func:`append_whole` ``data``, close it."""
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)
    try:
        append_whole(fd, data)
    finally:
        os.close(fd)
