"""``rbc fuzz``: a hostile-client campaign against drive_server, and healthy clients' latency beside it.

Phase 1 (campaign): ``--telemetries`` mixed telemetry events (good frames, bad base64, wrong image types
and sizes, decompression bombs, NaN/"abc"/locale/underscore/Arabic-Indic numbers, 400- and 5,000-digit
JSON integers, missing and extra keys, non-object payloads, 2,000-deep nesting, invalid JSON) over many
short connections, each ending with a normal close or a protocol error (binary Socket.IO packets "45"/"46",
garbage text, empty and binary frames, oversized or fragmented messages). Every telemetry must be answered
exactly once, in order, and every good frame with the same command as on a clean connection; a protocol
error must close its connection with a close frame.

Phase 2 (fairness): ``--healthy`` clients at 30 Hz, alone and beside two misbehaving clients (one writes
telemetries without reading its replies, one fuzzes as fast as it can), in separate processes; the two
conditions alternate every 2 s so that a shared machine's background load weighs on both alike.

Prints sent, answered, closes, crashes, double or missing answers, wrong commands, the server's RSS and
open file descriptors before and after (a started server only, from /proc), and round-trip percentiles.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import random
import socket
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from protocol import SteerCommand
from tools.bench.fuzz_campaign import Mix, Tally, fuzz_connection
from tools.wire.frames import SourceFrame as Frame

if TYPE_CHECKING:
    from multiprocessing.queues import Queue
    from multiprocessing.synchronize import Event
from tools.wire.unity_client import UnityWireClient

log = logging.getLogger("rbc.fuzz")






# -- phase 1 -------------------------------------------------------------------------------------------


# -- phase 2 -------------------------------------------------------------------------------------------
def _healthy(url: str, payload: dict[str, str], n: int, duration: float,
             out: Queue[list[tuple[float, float]]]) -> None:
    """``n`` closed-loop clients at 30 Hz for ``duration`` s; puts [(time.monotonic() sent, round trip s)]."""
    samples: list[tuple[float, float]] = []
    lock = threading.Lock()

    def one() -> None:
        with UnityWireClient(url) as client:
            client.exchange(payload)
            mine = []
            t_next = time.perf_counter()
            end = t_next + duration
            while t_next < end:
                sent = time.monotonic()
                mine.append((sent, client.exchange(payload)[1]))
                t_next += 1 / 30
                time.sleep(max(0.0, t_next - time.perf_counter()))
        with lock:
            samples.extend(mine)

    pool = [threading.Thread(target=one) for _ in range(n)]
    for t in pool:
        t.start()
    for t in pool:
        t.join()
    out.put(samples)


def _step_aside() -> None:
    """Run a misbehaving client only on CPU nobody else wants (Linux SCHED_IDLE, else nice 19): it stands
    in for a client on another machine, and must not slow the server or the healthy clients by taking
    their CPU, only by what it sends."""
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        os.nice(19)


def _flooder(url: str, stop: Event, nice: bool) -> None:
    """Writes manual-mode telemetries without ever reading; reconnects whenever it is dropped."""
    if nice:
        _step_aside()
    while not stop.is_set():
        try:
            client = UnityWireClient(url)
            client.connect()
            client.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            blob = client.telemetry_frame(None) * 2000
            while not stop.is_set():
                client.socket.sendall(blob)
        except (OSError, ConnectionError):
            time.sleep(0.05)


def _fuzzer(url: str, frames: list[Frame], reference: list[SteerCommand | None], stop: Event, nice: bool,
            seed: int) -> None:
    if nice:
        _step_aside()
    rng = random.Random(seed)
    mix = Mix(frames, rng)
    tally = Tally()
    while not stop.is_set():
        try:
            fuzz_connection(url, mix, reference, 200, tally, rng)
        except (OSError, ConnectionError, TimeoutError):
            time.sleep(0.05)


def _percentiles(rtts_s: list[float]) -> dict[str, float]:
    ms = np.asarray(rtts_s) * 1e3
    return {"frames": int(len(ms)), "p50_ms": round(float(np.percentile(ms, 50)), 3),
            "p99_ms": round(float(np.percentile(ms, 99)), 3), "max_ms": round(float(ms.max()), 3)}


def fairness(url: str, frames: list[Frame], reference: list[SteerCommand | None], healthy: int, duration: float,
             nice: bool, seed: int, phase_s: float = 2.0, settle_s: float = 0.3) -> tuple[dict, dict]:
    """Healthy clients' round trips alone and beside two misbehaving clients, as (alone, beside).

    Why interleaved: on a shared machine the background load drifts over a measurement. The healthy
    clients run throughout while the misbehaving pair is started and killed every ``phase_s``; each
    round trip is attributed to the phase it started in (the first ``settle_s`` of a phase is left out),
    so both conditions see the same background. ``duration`` is the time spent in each condition.
    """
    ctx = mp.get_context("fork")
    out = ctx.Queue()
    phases = max(1, round(duration / phase_s))
    proc = ctx.Process(target=_healthy, args=(url, frames[0].payload(), healthy, 2 * phases * phase_s + 1.0, out))
    proc.start()
    time.sleep(1.0)  # the healthy clients are connected and at their pace
    windows: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
    for k in range(2 * phases):
        misbehaving = k % 2 == 1
        t0 = time.monotonic()
        bad = []
        if misbehaving:
            stop = ctx.Event()
            bad = [ctx.Process(target=_flooder, args=(url, stop, nice), daemon=True),
                   ctx.Process(target=_fuzzer, args=(url, frames, reference, stop, nice, seed + k), daemon=True)]
            for p in bad:
                p.start()
        time.sleep(max(0.0, t0 + phase_s - time.monotonic()))
        windows[misbehaving].append((t0 + settle_s, time.monotonic()))
        for p in bad:
            p.kill()  # at once, as a client that vanishes: the server sees its connections end
            p.join()
    samples = out.get(timeout=2 * phases * phase_s + 120)
    proc.join()

    def within(kind: bool) -> list[float]:
        return [rtt for sent, rtt in samples if any(a <= sent < b for a, b in windows[kind])]

    return _percentiles(within(False)), _percentiles(within(True))


# -- measuring the server -----------------------------------------------------------------------------
def rss_mib(pid: int | None) -> float | None:
    if pid is None:
        return None
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return round(int(line.split()[1]) / 1024, 1)
    except OSError:
        return None
    return None


def open_fds(pid: int | None) -> int | None:
    try:
        return len(os.listdir(f"/proc/{pid}/fd")) if pid is not None else None
    except OSError:
        return None


def memory_report(rss: float | None, rss0: float | None, fds: int | None, fds0: int | None) -> str:
    """The server's RSS and open fds beside the baseline; a server gone meanwhile has no RSS (was: a traceback)."""
    change = f" ({rss - rss0:+.1f} MiB)" if rss is not None and rss0 is not None else ""
    return f"RSS {'unknown' if rss is None else f'{rss} MiB'}{change}, {fds} open fds (baseline {fds0})"


def settled_fds(pid: int | None, baseline: int | None, timeout: float = 10.0) -> int | None:
    """Open fds once closed connections are gone (the server closes them within a moment)."""
    deadline = time.monotonic() + timeout
    fds = open_fds(pid)
    while fds is not None and baseline is not None and fds > baseline and time.monotonic() < deadline:
        time.sleep(0.2)
        fds = open_fds(pid)
    return fds
