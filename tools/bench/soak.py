"""``rbc soak``: drive_server under a steady mix for a long time, and what drifted.

The mix (:mod:`tools.bench.soak_mix`) runs for ``duration_s`` beside ``--record`` on; every ``sample_s``
the server's RSS, open fds and the window's round-trip p50/p99 are sampled. After the run the server is
stopped (its recorder flushes) and every row of the recording is checked for its image.

Why threads in one process: the clients send pre-built frames and sleep most of the time (a simulator
at 30 Hz is idle 97 % of it), and the p99 compared is the first minute's against the last minute's, so a
constant client cost cancels out.
"""

from __future__ import annotations

import bisect
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np

from protocol.datalog import read_log
from protocol.errors import BadValue
from tools.bench.fuzz import open_fds, rss_mib, settled_fds
from tools.bench.soak_mix import REPLY_TIMEOUT_S, SoakMix, Tally
from tools.wire.frames import SourceFrame
from tools.wire.unity_client import UnityWireClient

__all__ = ["EDGE_WINDOW_S", "SampleRow", "Soak", "SoakConfig", "Tally", "check_recording"]

#: Length of the windows whose p99 are compared (the first and the last of the run).
EDGE_WINDOW_S = 60.0


@dataclass
class SoakConfig:
    """One soak: how long, how many driving clients, how often it samples (defaults defined once)."""

    duration_s: float = 3600.0
    clients: int = 4
    sample_s: float = 10.0
    min_hz: float = 15.0
    max_hz: float = 30.0
    malformed_every_s: float = 1.0
    reconnect_every_s: float = 0.5
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.duration_s > 0:
            raise BadValue(f"--duration must be > 0 s, got {self.duration_s}")
        if self.clients < 1:
            raise BadValue(f"--clients must be >= 1, got {self.clients}")
        if not 0 < self.sample_s <= self.duration_s:
            raise BadValue(f"--sample must be in (0, duration], got {self.sample_s}")

    def rates_hz(self) -> list[float]:
        if self.clients == 1:
            return [self.max_hz]
        return [float(r) for r in np.linspace(self.min_hz, self.max_hz, self.clients)]


class SampleRow(TypedDict):
    """One sample of the server every ``sample_s``: its memory, open files, and the latency of that window."""

    t_s: float
    rss_mib: float | None
    fds: int | None
    frames: int
    p50_ms: float | None
    p99_ms: float | None


class Soak(SoakMix):
    """One soak against the server at ``url`` (process ``pid``): the mix, and the sampler beside it."""

    def __init__(self, url: str, pid: int | None, frames: list[SourceFrame], config: SoakConfig) -> None:
        super().__init__(url, frames, config.malformed_every_s, config.reconnect_every_s)
        self.pid, self.config = pid, config
        self.samples: list[SampleRow] = []

    # -- the run ----------------------------------------------------------------------------------
    def run(self, progress: Callable[[float, SampleRow], None] | None = None) -> SoakResult:
        cfg = self.config
        with UnityWireClient(self.url, timeout=REPLY_TIMEOUT_S) as client:  # the recorder opens its log
            for payload in self.payloads[:3]:
                client.exchange(payload)
        time.sleep(1.0)  # the warm-up connection's socket is closed
        rss_before, fds_before = rss_mib(self.pid), open_fds(self.pid)
        self.t0 = time.perf_counter()
        threads = self.threads(cfg.rates_hz())
        for t in threads:
            t.start()
        next_sample = cfg.sample_s
        while True:
            now = time.perf_counter() - self.t0
            if now >= cfg.duration_s:
                break
            time.sleep(max(0.0, min(next_sample, cfg.duration_s) - now))
            now = time.perf_counter() - self.t0
            if now >= next_sample - 1e-6:
                frames, p50, p99 = self._window(next_sample - cfg.sample_s, next_sample)
                self.samples.append({"t_s": round(now, 1), "rss_mib": rss_mib(self.pid), "fds": open_fds(self.pid),
                                     "frames": frames, "p50_ms": p50, "p99_ms": p99})
                next_sample += cfg.sample_s
                if progress is not None:
                    progress(min(now, cfg.duration_s), self.samples[-1])
        rss_end, fds_running = rss_mib(self.pid), open_fds(self.pid)
        self.stop.set()
        for t in threads:
            t.join(REPLY_TIMEOUT_S * 3)
        fds_end = settled_fds(self.pid, fds_before)
        edge = min(EDGE_WINDOW_S, cfg.duration_s / 3)
        _, p50_first, p99_first = self._window(0.0, edge)
        _, p50_last, p99_last = self._window(cfg.duration_s - edge, cfg.duration_s)
        warm = next((s for s in self.samples if s["t_s"] >= edge), None)
        # the latency per whole window of EDGE_WINDOW_S (a p99 over 10 s is the 9th-worst frame)
        minutes: list[WindowRow] = []
        for k in range(int(cfg.duration_s // edge)):
            frames, p50, p99 = self._window(k * edge, (k + 1) * edge)
            minutes.append({"t_s": round((k + 1) * edge, 1), "frames": frames, "p50_ms": p50, "p99_ms": p99})
        tally = self.tally
        return {
            "duration_s": cfg.duration_s, "clients": cfg.clients, "rates_hz": [round(r, 1) for r in cfg.rates_hz()],
            "telemetries": tally.telemetries, "answered": tally.answered, "unanswered": tally.unanswered,
            "double_answered": tally.double_answered, "wrong_kind": tally.wrong_kind,
            "driving_disconnects": tally.disconnects, "malformed": tally.malformed, "reconnects": tally.reconnects,
            "idle_sessions": tally.idle_sessions, "live_events": tally.live_events,
            "rss_mib_before": rss_before, "rss_mib_start": warm["rss_mib"] if warm else None, "rss_mib_end": rss_end,
            "fds_start": fds_before, "fds_running_start": warm["fds"] if warm else None, "fds_running_end": fds_running,
            "fds_end": fds_end,
            "edge_window_s": edge, "p50_ms_first_minute": p50_first, "p99_ms_first_minute": p99_first,
            "p50_ms_last_minute": p50_last, "p99_ms_last_minute": p99_last,
            "samples": list(self.samples), "minutes": minutes, "errors": tally.errors,
        }

    def _window(self, a: float, b: float) -> tuple[int, float | None, float | None]:
        with self.lock:
            lists = list(self.rtts)
        ms: list[float] = []
        for rtts in lists:
            k = bisect.bisect_left(rtts, (a, -1.0))  # appended in time order
            ms.extend(rtt for t, rtt in itertools.takewhile(lambda x: x[0] < b, rtts[k:]))
        if not ms:
            return 0, None, None
        arr = np.asarray(ms) * 1e3
        return int(arr.size), round(float(np.percentile(arr, 50)), 3), round(float(np.percentile(arr, 99)), 3)


class WindowRow(TypedDict):
    """The latency of one whole window of ``edge_window_s``."""

    t_s: float
    frames: int
    p50_ms: float | None
    p99_ms: float | None


class SoakResult(TypedDict):
    """What :meth:`Soak.run` measured; ``rbc soak`` adds the recording's and the server's figures."""

    duration_s: float
    clients: int
    rates_hz: list[float]
    telemetries: int
    answered: int
    unanswered: int
    double_answered: int
    wrong_kind: int
    driving_disconnects: int
    malformed: int
    reconnects: int
    idle_sessions: int
    live_events: int
    rss_mib_before: float | None
    rss_mib_start: float | None
    rss_mib_end: float | None
    fds_start: int | None
    fds_running_start: int | None
    fds_running_end: int | None
    fds_end: int | None
    edge_window_s: float
    p50_ms_first_minute: float | None
    p99_ms_first_minute: float | None
    p50_ms_last_minute: float | None
    p99_ms_last_minute: float | None
    samples: list[SampleRow]
    minutes: list[WindowRow]
    errors: list[str]
    recorded_rows: NotRequired[int]
    recorded_missing_images: NotRequired[int]
    server_exit_code: NotRequired[int]
    server_tracebacks: NotRequired[int]
    server_faults: NotRequired[dict[str, int]]


def check_recording(folder: Path) -> tuple[int, int]:
    """(rows, rows whose centre image is missing or unreadable) of a ``--record`` folder, as the log reader
    that training uses sees them."""
    if not (folder / "driving_log.csv").is_file():
        return 0, 0
    _, report = read_log(folder)
    return report.rows, sum(1 for s in report.skipped if "image" in s.reason)
