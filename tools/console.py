"""Console output of long jobs: progress with a total."""

from __future__ import annotations

import logging

log = logging.getLogger(__name__)


class Progress:
    """tqdm when installed (the train extra), otherwise a log line every 10 %."""

    def __init__(self, desc: str, logger: logging.Logger = log) -> None:
        self.desc, self.log = desc, logger
        self._bar = None
        self._last = -1
        try:
            from tqdm import tqdm
        except ImportError:
            tqdm = None
        self._tqdm = tqdm

    def __call__(self, done: float, total: float) -> None:
        if self._tqdm is not None:
            if self._bar is None:
                self._bar = self._tqdm(total=round(total), desc=self.desc, unit="m", dynamic_ncols=True)
            self._bar.update(round(done) - self._bar.n)
            return
        tenth = int(10 * done / total) if total else 10
        if tenth > self._last:
            self._last = tenth
            self.log.info("%s: %3d %% (%.0f of %.0f m)", self.desc, 10 * tenth, done, total)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
