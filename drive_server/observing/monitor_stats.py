"""What a client's misbehaviour monitor did, kept with its latency statistics: frames and episodes per state, the
times it was switched off, and its score and time per frame (a ring like the stage timings), so the server log,
``--stats-json`` and ``rbc bench`` can say how often it warned and what it cost without a recording.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from drive_server.observing.ring import SampleRing

if TYPE_CHECKING:
    from drive_server.serving.client_monitor import ClientMonitor

#: The states, in order of severity (``drive_server.serving.client_monitor.Level``'s labels).
STATES = ("normal", "warning", "alarm")
#: Per-frame columns of the ring: the frame's own score and the monitor's time in seconds.
COLUMNS = ("score", "seconds")
_INITIAL_ROWS = 256


class MonitorSummary(TypedDict):
    """The ``monitor`` entry of a statistics summary."""

    frames: int  # frames the monitor scored
    states: dict[str, int]  # frames per state
    episodes: dict[str, int]  # entries into warning and into alarm
    switched_off: int  # clients whose monitor failed and was switched off
    sampled: int  # frames the percentiles are computed over
    score: dict[str, float]  # the frame score's p50, p99, max
    time_ms: dict[str, float]  # the monitor's time per frame: p50, p90, p99, max


class MonitorTally:
    """One client's monitor figures; ``note`` adds a frame (a row assignment, like the stage timings)."""

    def __init__(self, capacity: int) -> None:
        self.states = dict.fromkeys(STATES, 0)
        self.episodes = dict.fromkeys(STATES[1:], 0)
        self.switched_off = 0
        self._ring = SampleRing(len(COLUMNS), capacity, _INITIAL_ROWS)
        self._seen_off = False
        self._level = 0  # the state of the last frame noted, for counting entries

    def note(self, monitor: ClientMonitor) -> None:
        """The frame ``monitor`` just scored (its ``last`` reading), or its switching off (counted once)."""
        reading = monitor.last
        if monitor.failed is not None or reading is None:
            if monitor.failed is not None and not self._seen_off:
                self._seen_off = True
                self.switched_off += 1
            return
        level = int(reading.level)
        if level > self._level:
            self.episodes[STATES[level]] += 1
        self._level = level
        self.states[STATES[level]] += 1
        self._ring.add((reading.score, monitor.seconds))

    @property
    def frames(self) -> int:
        return sum(self.states.values())

    def samples(self) -> np.ndarray:
        """The retained frames' (score, seconds), oldest first."""
        return self._ring.samples()

    def counters(self) -> dict[str, object]:
        return {"states": dict(self.states), "episodes": dict(self.episodes), "switched_off": self.switched_off}

    def absorb(self, other: MonitorTally) -> None:
        """Add ``other``'s counters (a client too old to keep one by one)."""
        for k, n in other.states.items():
            self.states[k] += n
        for k, n in other.episodes.items():
            self.episodes[k] += n
        self.switched_off += other.switched_off

    @classmethod
    def restore(cls, samples: np.ndarray, counters: dict[str, object] | None) -> MonitorTally:
        """The tally saved as ``samples`` and ``counters`` (a worker process's hand-back)."""
        tally = cls(1)
        tally._ring = SampleRing.of(samples, len(COLUMNS))
        c = counters or {}
        for key, into in (("states", tally.states), ("episodes", tally.episodes)):
            found = c.get(key)
            if isinstance(found, dict):
                into.update({k: int(v) for k, v in found.items() if k in into})
        off = c.get("switched_off", 0)
        tally.switched_off = off if isinstance(off, int) else 0
        return tally


def summarize_monitor(tallies: Iterable[MonitorTally]) -> MonitorSummary | None:
    """Counters and percentiles over several clients' tallies; None when no client's monitor scored or failed."""
    tallies = list(tallies)
    if not any(t.frames or t.switched_off for t in tallies):
        return None
    rows = np.concatenate([t.samples() for t in tallies]).astype(np.float64)
    out: MonitorSummary = {
        "frames": sum(t.frames for t in tallies),
        "states": {k: sum(t.states[k] for t in tallies) for k in STATES},
        "episodes": {k: sum(t.episodes[k] for t in tallies) for k in STATES[1:]},
        "switched_off": sum(t.switched_off for t in tallies),
        "sampled": len(rows), "score": {}, "time_ms": {}}
    if len(rows):
        s50, s99 = np.percentile(rows[:, 0], [50, 99])
        out["score"] = {"p50": round(float(s50), 6), "p99": round(float(s99), 6),
                        "max": round(float(rows[:, 0].max()), 6)}
        t = np.percentile(rows[:, 1], [50, 90, 99]) * 1e3
        out["time_ms"] = {"p50": round(float(t[0]), 4), "p90": round(float(t[1]), 4), "p99": round(float(t[2]), 4),
                          "max": round(float(rows[:, 1].max() * 1e3), 4)}
    return out


def monitor_line(summary: MonitorSummary) -> str:
    """The monitor's part of a log line: frames per state, episodes, and its time p50/p99."""
    states, episodes = summary["states"], summary["episodes"]
    line = (f"monitor: warning {states['warning']} alarm {states['alarm']} of {summary['frames']} frames "
            f"({episodes['warning']} warning, {episodes['alarm']} alarm episodes)")
    if summary["score"]:
        line += f", score p50/p99 {summary['score']['p50']:.4g}/{summary['score']['p99']:.4g}"
    if summary["time_ms"]:
        line += f", p50/p99 {summary['time_ms']['p50']:.3f}/{summary['time_ms']['p99']:.3f} ms"
    if summary["switched_off"]:
        line += f", switched off for {summary['switched_off']} client(s)"
    return line
