"""Console output of long jobs: progress bars with a total, on a terminal only.

A bar (tqdm, from the train extra) is drawn only when stderr is a terminal, so logs, pipes and CI
output stay clean; log lines are routed through tqdm while a command runs (:func:`console`), so
bars and log lines never interleave. Without tqdm or a terminal, progress is silent.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Literal, NoReturn

if TYPE_CHECKING:
    from tqdm import tqdm

log = logging.getLogger(__name__)


def _tqdm() -> type[tqdm[NoReturn]] | None:
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm


def interactive() -> bool:
    """Whether progress bars are wanted: stderr is a terminal and tqdm is installed."""
    return sys.stderr.isatty() and _tqdm() is not None


def bar(total: float | None, desc: str, unit: str) -> tqdm[NoReturn] | None:
    """A tqdm bar on a terminal, else None."""
    if not sys.stderr.isatty() or (make := _tqdm()) is None:  # not interactive()
        return None
    return make(total=total, desc=desc, unit=unit, dynamic_ncols=True, leave=True)


@contextlib.contextmanager
def console() -> Iterator[None]:
    """Route log records through tqdm while a command runs, so they never break a bar."""
    if not interactive():
        yield
        return
    from tqdm.contrib.logging import logging_redirect_tqdm

    with logging_redirect_tqdm():
        yield


class Progress:
    """A ``progress(done, total)`` callback drawing a bar in metres; ``close`` ends it."""

    def __init__(self, desc: str, unit: str = "m") -> None:
        self.desc, self.unit = desc, unit
        self._bar: tqdm[NoReturn] | Literal[False] | None = None

    def __call__(self, done: float, total: float) -> None:
        if self._bar is None:
            self._bar = bar(round(total), self.desc, self.unit) or False
        if self._bar:
            self._bar.total = round(total)
            self._bar.update(round(done) - self._bar.n)

    def close(self) -> None:
        if self._bar:
            self._bar.close()
        self._bar = None


class RunProgress:
    """Finished runs of an evaluation against the most it can take; the last run's outcome as postfix."""

    def __init__(self, most: int) -> None:
        self._bar = bar(most, "runs", "run")

    def record(self, record: Mapping[str, object]) -> None:
        msg = f"{record['experiment']}={record['value']} seed {record['seed']}: " \
              f"{'ok' if record['autonomous'] else 'intervention'}"
        log.debug("%s", msg)
        if self._bar is not None:
            self._bar.update(1)
            self._bar.set_postfix_str(msg)

    def close(self, finished: bool = True) -> None:
        """End the bar; a finished search shows 100 % (range searches stop before their most)."""
        if self._bar is None:
            return
        if finished:
            self._bar.total = self._bar.n
            self._bar.refresh()
        self._bar.close()
        self._bar = None
