"""Frame time stamps from Udacity file names, and the sessions they split a recording into.

The simulator names each frame ``center_2016_12_01_13_30_48_287.jpg``: the wall-clock time of the
frame to the millisecond. The log has no time column, so these names are the only clock there is: the
frame rate, and where a recording was paused and resumed (a session ends where the clock jumps).
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Sequence
from pathlib import PurePath

import numpy as np

_STAMP = re.compile(r"_(\d{4})_(\d{2})_(\d{2})_(\d{2})_(\d{2})_(\d{2})_(\d{3})$")
_EPOCH = dt.datetime(1970, 1, 1)


def frame_time(name: str | PurePath) -> float | None:
    """Seconds (naive local time) in a frame name ending ``_YYYY_MM_DD_HH_MM_SS_mmm``; None if it has none."""
    m = _STAMP.search(PurePath(name).stem)
    if not m:
        return None
    year, month, day, hour, minute, second, ms = (int(g) for g in m.groups())
    try:
        when = dt.datetime(year, month, day, hour, minute, second)
    except ValueError:  # month 13 and the like: not a time stamp
        return None
    return (when - _EPOCH).total_seconds() + ms / 1000


def session_ids(times: Sequence[float | None], gap_s: float) -> list[int]:
    """Session number (1, 2, ...) of each row in log order: a new one starts where the clock jumps by more
    than ``gap_s`` seconds, forwards or backwards. Undated rows belong to the session of the row before."""
    ids: list[int] = []
    session, last = 1, None
    for t in times:
        if t is not None:
            if last is not None and abs(t - last) > gap_s:
                session += 1
            last = t
        ids.append(session)
    return ids


def frame_intervals(times: Sequence[float | None], gap_s: float) -> np.ndarray:
    """Positive intervals between consecutive dated rows within a session (repeated stamps left out)."""
    dated = np.array([t for t in times if t is not None], np.float64)
    steps = np.diff(dated)
    return steps[(steps > 0) & (steps <= gap_s)]
