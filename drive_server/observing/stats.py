"""Per-client latency statistics of the serving pipeline, cheap enough to record on every frame.

Stage durations go into a numpy ring that grows to at most the last 65,536 frames (1.3 MB), so
recording costs a row assignment and memory stays bounded however long the simulator drives;
percentiles are computed only when a summary is asked for, over all retained frames or over the
frames since a given one (the periodic log line, so it stays cheap and describes recent latency).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np

from drive_server.observing.monitor_stats import MonitorSummary, MonitorTally, monitor_line, summarize_monitor
from drive_server.observing.ring import SampleRing
from protocol.runrecords import atomic_path

#: Pipeline stages, in order; ``total`` is handler entry to reply queued.
STAGES = ("decode", "preprocess", "inference", "control", "total")
RING_CAPACITY = 1 << 16
_INITIAL_ROWS = 1024


class StatsSummary(TypedDict):
    """What :func:`summarize` reports (the ``total`` and per-client entries of ``--stats-json``)."""

    frames: int
    manual: int
    malformed: int
    bad_input: dict[str, int]  # ``malformed`` by kind of bad input
    bad_output: int
    sampled: int  # frames the percentiles are computed over
    stages_ms: dict[str, dict[str, float]]  # stage -> p50, p90, p99, mean, max (empty without samples)
    monitor: NotRequired[MonitorSummary]  # only when a client's monitor scored a frame or was switched off


class LatencyStats:
    """Stage timings (seconds) and frame counters of one client."""

    def __init__(self, name: str = "", capacity: int = RING_CAPACITY) -> None:
        self.name = name
        self.frames = 0  # frames answered with the model's command
        self.manual = 0  # null (manual mode) frames
        self.malformed = 0  # frames answered by the fallback policy because the INPUT was unusable
        self.bad_input: dict[str, int] = {}  # ``malformed`` by kind of bad input (image, number, payload, json)
        self.bad_output = 0  # frames answered by the fallback policy because the MODEL's output was not finite
        self._ring = SampleRing(len(STAGES), capacity, _INITIAL_ROWS)
        self.monitor = MonitorTally(capacity)  # what the client's misbehaviour monitor did (none: empty)

    @property
    def recorded(self) -> int:
        """Frames whose timings went into the ring (``frames`` may also count others)."""
        return self._ring.recorded

    def record(self, timings: tuple[float, float, float, float, float]) -> None:
        self._ring.add(timings)
        self.frames += 1

    def count_bad_input(self, kind: str) -> None:
        self.malformed += 1
        self.bad_input[kind] = self.bad_input.get(kind, 0) + 1

    def absorb_counters(self, other: LatencyStats) -> None:
        """Add ``other``'s counters to these (statistics of clients too old to keep one by one)."""
        self.frames += other.frames
        self.manual += other.manual
        self.malformed += other.malformed
        self.bad_output += other.bad_output
        self.monitor.absorb(other.monitor)
        for kind, n in other.bad_input.items():
            self.bad_input[kind] = self.bad_input.get(kind, 0) + n

    def samples(self, since: int = 0) -> np.ndarray:
        """Timings of the retained frames numbered ``since`` and later, oldest first; shape (n, len(STAGES))."""
        return self._ring.samples(since)

    def summary(self) -> StatsSummary:
        return summarize([self])

    @classmethod
    def from_samples(cls, name: str, samples: np.ndarray, frames: int, manual: int, malformed: int,
                     bad_input: dict[str, int] | None = None, bad_output: int = 0) -> LatencyStats:
        """Rebuild statistics from saved samples (how a worker process hands its statistics back)."""
        stats = cls(name, capacity=max(1, len(samples)))
        stats._ring = SampleRing.of(samples, len(STAGES))
        stats.frames, stats.manual, stats.malformed = frames, manual, malformed
        stats.bad_input, stats.bad_output = dict(bad_input or {}), bad_output
        return stats


class FaultCounters:
    """Server-wide counts of what a client did wrong or the server refused, by kind (``FaultLog`` adds to it):
    protocol_error, message_too_large, header_timeout, refused, evicted, slow_reader (disconnected for
    not reading its replies)."""

    def __init__(self) -> None:
        self.counts: dict[str, int] = {}

    def add(self, kind: str, n: int = 1) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + n

    def merge(self, counts: dict[str, int]) -> None:
        for kind, n in counts.items():
            self.add(kind, n)

    def as_dict(self) -> dict[str, int]:
        return dict(sorted(self.counts.items()))


def save_stats(path: Path, stats: Iterable[LatencyStats]) -> None:
    """Save counters and retained samples of several clients to one ``.npz`` (atomically)."""
    path = Path(path)
    arrays: dict[str, np.ndarray] = {}
    meta = []
    for i, s in enumerate(stats):
        arrays[f"s{i}"], arrays[f"m{i}"] = s.samples(), s.monitor.samples()
        meta.append({"name": s.name, "frames": s.frames, "manual": s.manual, "malformed": s.malformed,
                     "bad_input": s.bad_input, "bad_output": s.bad_output, "monitor": s.monitor.counters()})
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    with atomic_path(path) as tmp, tmp.open("wb") as fh:  # a file object: np.savez would add ".npz" to a name
        # allow_pickle spelled out (numpy's default): else numpy's stub reads **arrays as possibly naming it
        np.savez(fh, allow_pickle=True, **arrays)


def load_stats(path: Path) -> list[LatencyStats]:
    """The statistics saved by ``save_stats``."""
    with np.load(Path(path)) as data:
        meta = json.loads(data["meta"].tobytes().decode())
        out = []
        for i, m in enumerate(meta):
            stats = LatencyStats.from_samples(m["name"], data[f"s{i}"], m["frames"], m["manual"], m["malformed"],
                                              m.get("bad_input"), m.get("bad_output", 0))
            if f"m{i}" in data:
                stats.monitor = MonitorTally.restore(data[f"m{i}"], m.get("monitor"))
            out.append(stats)
        return out


def summarize(stats: Iterable[LatencyStats], since: dict[str, int] | None = None) -> StatsSummary:
    """Counters and per-stage percentiles (milliseconds) over one or several clients.

    ``since`` maps a client's name to the first frame to include in the percentiles (counters are
    always totals).
    """
    stats = list(stats)
    since = since or {}
    samples = [s.samples(since.get(s.name, 0)) for s in stats]
    timings = np.concatenate(samples).astype(np.float64) if samples else np.zeros((0, len(STAGES)))
    out: StatsSummary = {
        "frames": sum(s.frames for s in stats),
        "manual": sum(s.manual for s in stats),
        "malformed": sum(s.malformed for s in stats),
        "bad_input": _sum_kinds(s.bad_input for s in stats),
        "bad_output": sum(s.bad_output for s in stats),
        "sampled": len(timings),
        "stages_ms": {},
    }
    monitor = summarize_monitor(s.monitor for s in stats)
    if monitor is not None:
        out["monitor"] = monitor
    if len(timings):
        pct = np.percentile(timings, [50, 90, 99], axis=0) * 1e3
        for i, stage in enumerate(STAGES):
            out["stages_ms"][stage] = {
                "p50": round(float(pct[0, i]), 4), "p90": round(float(pct[1, i]), 4),
                "p99": round(float(pct[2, i]), 4), "mean": round(float(timings[:, i].mean() * 1e3), 4),
                "max": round(float(timings[:, i].max() * 1e3), 4),
            }
    return out


def _sum_kinds(counts: Iterable[dict[str, int]]) -> dict[str, int]:
    total: dict[str, int] = {}
    for c in counts:
        for kind, n in c.items():
            total[kind] = total.get(kind, 0) + n
    return dict(sorted(total.items()))


def summary_line(summary: StatsSummary) -> str:
    """One log line: counters, then p50/p99 in ms per stage, then the kinds of bad input and bad output."""
    head = f"frames {summary['frames']} manual {summary['manual']} malformed {summary['malformed']}"
    tail = ""
    if summary.get("bad_input"):
        tail += " | malformed: " + ", ".join(f"{kind} {n}" for kind, n in summary["bad_input"].items())
    if summary.get("bad_output"):
        tail += f" | non-finite model output {summary['bad_output']}"
    if "monitor" in summary:
        tail += " | " + monitor_line(summary["monitor"])
    stages = summary["stages_ms"]
    if not stages:
        return head + tail
    return head + " | p50/p99 ms " + " ".join(
        f"{name} {stages[name]['p50']:.3f}/{stages[name]['p99']:.3f}" for name in STAGES) + tail
