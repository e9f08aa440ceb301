"""A float32 ring of per-frame rows that grows to a fixed capacity: recording a frame is one row assignment.

The stage timings and the monitor's figures of every client are kept this way, so a client that drives for an
hour costs at most ``capacity`` rows and a client of a few frames only the first block.
"""

from __future__ import annotations

import numpy as np


class SampleRing:
    """The last ``capacity`` rows of ``columns`` float32 values, oldest first in :meth:`samples`."""

    def __init__(self, columns: int, capacity: int, initial_rows: int) -> None:
        self.columns = columns
        self.capacity = capacity
        self.recorded = 0  # rows added, including those overwritten since
        self._rows = np.zeros((min(capacity, initial_rows), columns), np.float32)

    def add(self, row: tuple[float, ...]) -> None:
        if self.recorded == len(self._rows) < self.capacity:  # grow until the ring is full size
            self._rows = np.concatenate([self._rows, np.zeros_like(self._rows[: self.capacity - len(self._rows)])])
        self._rows[self.recorded % len(self._rows)] = row
        self.recorded += 1

    def samples(self, since: int = 0) -> np.ndarray:
        """The retained rows numbered ``since`` and later, oldest first; shape (n, columns)."""
        start = max(since, self.recorded - len(self._rows), 0)
        if start >= self.recorded:
            return self._rows[:0]
        return self._rows[np.arange(start, self.recorded) % len(self._rows)]

    @classmethod
    def of(cls, rows: np.ndarray, columns: int) -> SampleRing:
        """A full ring holding ``rows`` (saved samples handed back by a worker process)."""
        rows = np.asarray(rows, np.float32).reshape(-1, columns)
        ring = cls(columns, max(1, len(rows)), max(1, len(rows)))
        if len(rows):
            ring._rows, ring.recorded = rows, len(rows)
        return ring
