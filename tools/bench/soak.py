"""``rbc soak``: drive_server under a steady mix for a long time, and what drifted.

The mix, all at once for ``duration_s``: ``clients`` Unity-wire simulators in closed loop on real frames
at 15-30 Hz (spread evenly), one client that reconnects in a loop, one that upgrades and then says nothing
(until the server drops it, then again), a trickle of malformed telemetries between good ones, the live
view's event stream open, and ``--record`` on. Every ``sample_s`` the server's RSS, open fds and the
window's round-trip p50/p99 are sampled.

Exactly-once is checked the way ``rbc fuzz`` checks it: every 50 frames (and at the end) a client sends a
null telemetry, which the server answers with ``manual``; a ``steer`` read before that ``manual`` is an
extra answer (counted ``double_answered``), and a telemetry with no reply within the client timeout is
``unanswered`` (the client then reconnects). After the run the server is stopped (its recorder flushes)
and every row of the recording is checked for its image.

Why threads in one process: the clients send pre-built frames and sleep most of the time (a simulator
at 30 Hz is idle 97 % of it), and the p99 compared is the first minute's against the last minute's, so a
constant client cost cancels out.
"""

from __future__ import annotations

import bisect
import csv
import itertools
import logging
import threading
import time
import urllib.request
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from protocol import SteerCommand
from tools.bench.fuzz import open_fds, rss_mib, settled_fds
from tools.wire.frames import SourceFrame
from tools.wire.unity_client import ConnectionClosed, UnityWireClient

log = logging.getLogger("rbc.soak")

#: A null telemetry: the server answers it with ``manual`` (the sentinel of the exactly-once check).
SENTINEL = '42["telemetry",null]'
#: Frames between two sentinels on a driving client.
SENTINEL_EVERY = 50
#: Seconds a telemetry may wait for its reply before it counts as unanswered.
REPLY_TIMEOUT_S = 5.0
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
            raise ValueError(f"--duration must be > 0 s, got {self.duration_s}")
        if self.clients < 1:
            raise ValueError(f"--clients must be >= 1, got {self.clients}")
        if not 0 < self.sample_s <= self.duration_s:
            raise ValueError(f"--sample must be in (0, duration], got {self.sample_s}")

    def rates_hz(self) -> list[float]:
        if self.clients == 1:
            return [self.max_hz]
        return [float(r) for r in np.linspace(self.min_hz, self.max_hz, self.clients)]


@dataclass
class Tally:
    """What one client (or all of them) sent and got back; guarded by the owner's lock when shared."""

    telemetries: int = 0
    answered: int = 0
    unanswered: int = 0
    double_answered: int = 0
    wrong_kind: int = 0  # a steer where manual was due, or the other way round
    disconnects: int = 0  # the server closed a driving client's connection (it reconnects)
    malformed: int = 0
    reconnects: int = 0
    idle_sessions: int = 0
    live_events: int = 0
    errors: list[str] = field(default_factory=list)

    def add(self, other: Tally) -> None:
        for name, value in asdict(other).items():
            if name == "errors":
                self.errors.extend(other.errors[:20 - len(self.errors)])
            else:
                setattr(self, name, getattr(self, name) + value)


@dataclass
class Sample:
    t_s: float
    rss_mib: float | None
    fds: int | None
    frames: int
    p50_ms: float | None
    p99_ms: float | None


class Soak:
    """The clients and the sampler of one soak against the server at ``url`` (process ``pid``)."""

    def __init__(self, url: str, pid: int | None, frames: list[SourceFrame], config: SoakConfig) -> None:
        self.url, self.pid, self.config = url, pid, config
        self.payloads = [f.payload() for f in frames]
        self.stop = threading.Event()
        self.lock = threading.Lock()
        self.tally = Tally()
        # per driving client, (seconds since start, round trip s) in time order; appended by its thread only
        self.rtts: list[list[tuple[float, float]]] = []
        self.samples: list[Sample] = []
        self.t0 = 0.0

    # -- the clients ------------------------------------------------------------------------------
    def _sentinel(self, client: UnityWireClient, tally: Tally) -> None:
        """Send the null telemetry and read up to its ``manual``: every steer before it was an extra answer."""
        client.send_text(SENTINEL)
        tally.telemetries += 1
        while True:
            reply = client.receive_reply(REPLY_TIMEOUT_S)
            if reply is None:
                tally.answered += 1
                return
            tally.double_answered += 1

    def _exchange(self, client: UnityWireClient, payload: dict[str, Any] | None, tally: Tally,
                  expect_steer: bool) -> float | None:
        tally.telemetries += 1
        try:
            reply, rtt = client.exchange(payload)
        except TimeoutError:
            tally.unanswered += 1
            raise
        tally.answered += 1
        if isinstance(reply, SteerCommand) != expect_steer:
            tally.wrong_kind += 1
        return rtt

    def _reconnecting(self) -> None:
        tally = Tally()
        while not self.stop.is_set():
            try:
                with UnityWireClient(self.url, timeout=REPLY_TIMEOUT_S) as client:
                    for k in range(2):
                        self._exchange(client, self.payloads[k], tally, True)
                tally.reconnects += 1
            except (ConnectionClosed, OSError, TimeoutError) as exc:
                tally.errors.append(f"reconnecting client: {exc}")
            self.stop.wait(self.config.reconnect_every_s)
        with self.lock:
            self.tally.add(tally)

    def _idle(self) -> None:
        """Upgrade, then send nothing (pings read, never answered) until the server drops the connection
        (its ping timeout) or the soak ends; then again."""
        tally = Tally()
        while not self.stop.is_set():
            try:
                client = UnityWireClient(self.url, timeout=REPLY_TIMEOUT_S)
                client.connect()
            except (ConnectionError, OSError) as exc:
                tally.errors.append(f"idle client: {exc}")
                self.stop.wait(1.0)
                continue
            tally.idle_sessions += 1
            sock = client.socket
            sock.settimeout(1.0)
            while not self.stop.is_set():
                try:
                    if sock.recv(4096) == b"":  # read (so the kernel's buffer never fills) and never answered
                        break  # closed by the server
                except TimeoutError:
                    continue
                except OSError:
                    break
            client.close()
        with self.lock:
            self.tally.add(tally)

    def _malformed(self) -> None:
        """Between good frames, now and then a telemetry no simulator would send; each must be answered."""
        tally = Tally()
        good = self.payloads[0]
        bad = [dict(good, image="not base64 at all"), dict(good, speed="abc"),
               {k: v for k, v in good.items() if k != "image"}, dict(good, steering_angle="1_000")]
        k = 0
        while not self.stop.is_set():
            try:
                with UnityWireClient(self.url, timeout=REPLY_TIMEOUT_S) as client:
                    while not self.stop.is_set():
                        self._exchange(client, bad[k % len(bad)], tally, True)  # answered with the fallback
                        tally.malformed += 1
                        k += 1
                        for _ in range(4):  # good frames again (the fallback holds, then the car drives on)
                            self.stop.wait(self.config.malformed_every_s / 5)
                            self._exchange(client, good, tally, True)
            except (ConnectionClosed, OSError, TimeoutError) as exc:
                tally.disconnects += 1
                tally.errors.append(f"malformed client: {exc}")
                self.stop.wait(0.2)
        with self.lock:
            self.tally.add(tally)

    def _live_view(self) -> None:
        tally = Tally()
        while not self.stop.is_set():
            try:
                with urllib.request.urlopen(self.url + "/events", timeout=5) as stream:
                    while not self.stop.is_set():
                        line = stream.readline()
                        if not line:
                            break
                        if line.startswith(b"data:"):
                            tally.live_events += 1
            except OSError as exc:
                tally.errors.append(f"live view: {exc}")
                self.stop.wait(1.0)
        with self.lock:
            self.tally.add(tally)

    # -- the run ----------------------------------------------------------------------------------
    def run(self, progress: Any = None) -> dict[str, Any]:
        cfg = self.config
        with UnityWireClient(self.url, timeout=REPLY_TIMEOUT_S) as client:  # the recorder opens its log
            for payload in self.payloads[:3]:
                client.exchange(payload)
        time.sleep(1.0)  # the warm-up connection's socket is closed
        rss_before, fds_before = rss_mib(self.pid), open_fds(self.pid)
        self.t0 = time.perf_counter()
        threads = [threading.Thread(target=self._driving, args=(hz, 7 * n), daemon=True)
                   for n, hz in enumerate(cfg.rates_hz())]
        threads += [threading.Thread(target=f, daemon=True)
                    for f in (self._reconnecting, self._idle, self._malformed, self._live_view)]
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
                self.samples.append(Sample(round(now, 1), rss_mib(self.pid), open_fds(self.pid), frames, p50, p99))
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
        warm = next((s for s in self.samples if s.t_s >= min(EDGE_WINDOW_S, cfg.duration_s / 3)), None)
        minutes = []  # the latency per whole window of EDGE_WINDOW_S (a p99 over 10 s is the 9th-worst frame)
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
            "rss_mib_before": rss_before, "rss_mib_start": warm.rss_mib if warm else None, "rss_mib_end": rss_end,
            "fds_start": fds_before, "fds_running_start": warm.fds if warm else None, "fds_running_end": fds_running,
            "fds_end": fds_end,
            "edge_window_s": edge, "p50_ms_first_minute": p50_first, "p99_ms_first_minute": p99_first,
            "p50_ms_last_minute": p50_last, "p99_ms_last_minute": p99_last,
            "samples": [asdict(s) for s in self.samples], "minutes": minutes, "errors": tally.errors,
        }

    def _window(self, a: float, b: float) -> tuple[int, float | None, float | None]:
        with self.lock:
            lists = list(self.rtts)
        ms = []
        for rtts in lists:
            k = bisect.bisect_left(rtts, (a, -1.0))  # appended in time order
            ms.extend(rtt for t, rtt in itertools.takewhile(lambda x: x[0] < b, rtts[k:]))
        if not ms:
            return 0, None, None
        arr = np.asarray(ms) * 1e3
        return int(arr.size), round(float(np.percentile(arr, 50)), 3), round(float(np.percentile(arr, 99)), 3)

    def _driving(self, rate_hz: float, offset: int) -> None:
        """A simulator in closed loop at ``rate_hz`` on the real frames (from frame ``offset``)."""
        tally = Tally()
        rtts: list[tuple[float, float]] = []
        with self.lock:
            self.rtts.append(rtts)
        period = 1.0 / rate_hz
        i = offset
        while not self.stop.is_set():
            try:
                with UnityWireClient(self.url, timeout=REPLY_TIMEOUT_S) as client:
                    t_next = time.perf_counter()
                    while not self.stop.is_set():
                        sent = time.perf_counter() - self.t0
                        rtt = self._exchange(client, self.payloads[i % len(self.payloads)], tally, True)
                        rtts.append((sent, rtt))
                        i += 1
                        if i % SENTINEL_EVERY == 0:
                            self._sentinel(client, tally)
                        t_next += period
                        time.sleep(max(0.0, t_next - time.perf_counter()))
                    self._sentinel(client, tally)
            except (ConnectionClosed, OSError, TimeoutError) as exc:
                tally.disconnects += 1
                tally.errors.append(f"driving client: {exc}")
                self.stop.wait(0.2)
        with self.lock:
            self.tally.add(tally)


def check_recording(folder: Path) -> tuple[int, int]:
    """(rows, rows whose centre image is missing or empty) of a ``--record`` folder."""
    log_path = folder / "driving_log.csv"
    if not log_path.is_file():
        return 0, 0
    rows = missing = 0
    with log_path.open(newline="", encoding="utf-8") as f:
        for row in csv.reader(f):
            if not row:
                continue
            rows += 1
            image = Path(row[0].strip())
            if not image.is_absolute():
                image = folder / image
            if not image.is_file() or image.stat().st_size == 0:
                missing += 1
    return rows, missing
