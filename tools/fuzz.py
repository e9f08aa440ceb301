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

import argparse
import base64
import json
import logging
import multiprocessing as mp
import os
import random
import socket
import struct
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from protocol import SteerCommand
from tools.frames import Frame, log_frames, synthetic_frames
from tools.server_process import ServerProcess
from tools.unity_client import ConnectionClosed, UnityWireClient, mask_payload

log = logging.getLogger("rbc.fuzz")

DEFAULT_LOG = Path(__file__).resolve().parents[1] / "tests" / "data" / "udacity-sample"
WINDOW = 8  # telemetries in flight per fuzz connection (then their replies are read)
MANUAL = "manual"
STEER = "steer"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--server", default=None, help="fuzz a running server at this URL instead of starting one "
                   "(then RSS and file descriptors are measured only with --pid)")
    p.add_argument("--pid", type=int, default=None, help="process id of the --server, for RSS and fd counts")
    p.add_argument("--model", type=Path, default=None, help="ONNX model of the started server (default: bundled)")
    p.add_argument("--server-args", default="", help="extra drive_server arguments, e.g. \"--max-pending 32\"")
    p.add_argument("--telemetries", type=int, default=100_000, help="telemetries of the campaign (default 100,000)")
    p.add_argument("--healthy", type=int, default=8, help="healthy 30 Hz clients in the fairness phase (default 8)")
    p.add_argument("--duration", type=float, default=20.0,
                   help="seconds of each fairness condition, interleaved in 2 s phases (default 20)")
    p.add_argument("--no-nice", action="store_true",
                   help="run the misbehaving clients at normal priority (by default they get only idle CPU, "
                        "standing in for clients on other machines, so they do not take the server's or the "
                        "healthy clients' CPU here)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", type=Path, default=None, help="also write the figures as JSON here")


# -- what a hostile client sends ---------------------------------------------------------------------
def _bomb_b64(good_b64: str, width: int = 30000, height: int = 30000) -> str:
    """A real JPEG whose start-of-frame marker claims ``width`` x ``height`` pixels."""
    raw = base64.b64decode(good_b64)
    pos = 2
    while raw[pos + 1] not in (0xC0, 0xC1, 0xC2):
        pos += 2 + struct.unpack_from(">H", raw, pos + 2)[0]
    return base64.b64encode(raw[:pos + 5] + struct.pack(">HH", height, width) + raw[pos + 9:]).decode()


def _small_jpeg_b64() -> str:
    import cv2

    ok, buf = cv2.imencode(".jpg", np.zeros((50, 100, 3), np.uint8))
    return base64.b64encode(buf.tobytes()).decode()


class Mix:
    """Telemetry events (text of the Engine.IO packet, expected reply, key of a good frame or None)."""

    def __init__(self, frames: list[Frame], rng: random.Random) -> None:
        self.rng = rng
        self.good = [f.payload() for f in frames]
        g = self.good[0]
        bomb, small = _bomb_b64(g["image"]), _small_jpeg_b64()
        event = '42["telemetry",{}]'.format
        bad_payloads: list[Any] = [
            dict(g, image="!!!not base64!!!"), dict(g, image=base64.b64encode(b"GIF89a" + bytes(64)).decode()),
            dict(g, image=small), dict(g, image=bomb), dict(g, image=g["image"][: len(g["image"]) // 3]),
            dict(g, image=12), dict(g, speed="NaN"), dict(g, speed="abc"), dict(g, speed="1_000"),
            dict(g, speed="\u0661\u0662"), dict(g, speed="\uff11\uff12"), dict(g, speed="-1e308"),
            dict(g, speed="1e400"), dict(g, throttle="0,5.0"), dict(g, speed=True),
            {k: v for k, v in g.items() if k != "image"}, {"steering_angle": "0"}, {}, [1, 2, 3], "text", 42,
        ]
        self.bad = [event(json.dumps(p)) for p in bad_payloads]
        self.bad += [
            event("[" * 2000 + "]" * 2000), event(json.dumps(dict(g, speed=0))[:-1].replace('"speed": 0', '"speed": '
                                                                                          + "9" * 400) + "}"),
            event('{"speed": 1' + "0" * 5000 + "}"), '42["telemetry",{"speed":"1"', event('{"a": 1}, "extra"'),
        ]

    def telemetry(self) -> tuple[str, str, int | None]:
        r = self.rng.random()
        if r < 0.35:
            i = self.rng.randrange(len(self.good))
            payload = dict(self.good[i])
            if self.rng.random() < 0.3:  # a European locale: the same command
                payload = {k: (v.replace(".", ",") if k != "image" else v) for k, v in payload.items()}
            if self.rng.random() < 0.2:  # extra keys are ignored
                payload["extra"] = "x"
            return '42["telemetry",' + json.dumps(payload) + "]", STEER, i
        if r < 0.45:
            return '42["telemetry",null]', MANUAL, None
        return self.rng.choice(self.bad), STEER, None


def _frame(opcode: int, payload: bytes, fin: bool = True) -> bytes:
    n = len(payload)
    b0 = (0x80 if fin else 0) | opcode
    header = struct.pack("!BB", b0, 0x80 | n) if n < 126 else (
        struct.pack("!BBH", b0, 0x80 | 126, n) if n < 65536 else struct.pack("!BBQ", b0, 0x80 | 127, n))
    mask = os.urandom(4)
    return header + mask + mask_payload(payload, mask)


PROTOCOL_ERRORS: tuple[bytes, ...] = (
    _frame(0x1, b"45"), _frame(0x1, b"46"), _frame(0x1, b"hello"), _frame(0x1, b""), _frame(0x1, b"4[[[[]]]]"),
    _frame(0x2, b"\x00\x01binary"), _frame(0x1, b'42["telemetry",{"image":"' + b"A" * 400_000 + b'"}]'),
    _frame(0x1, b"4" + b"A" * 200_000, fin=False) + _frame(0x0, b"A" * 200_000, fin=False),
)


# -- phase 1 -------------------------------------------------------------------------------------------
class Tally:
    def __init__(self) -> None:
        self.sent = self.answered = self.connections = self.closed_on_error = 0
        self.mismatched = self.wrong_commands = self.lost = 0
        self.lock = threading.Lock()

    def add(self, **counts: int) -> None:
        with self.lock:
            for k, v in counts.items():
                setattr(self, k, getattr(self, k) + v)


def _reply_kind(reply: SteerCommand | None) -> str:
    return MANUAL if reply is None else STEER


def fuzz_connection(url: str, mix: Mix, reference: list[SteerCommand], batch: int, tally: Tally,
                    rng: random.Random) -> None:
    """One connection: ``batch`` telemetries in windows, a sentinel, then a normal close or a protocol error."""
    with UnityWireClient(url) as client:
        tally.add(connections=1)
        sent = answered = mismatched = wrong = 0
        remaining = batch
        while remaining > 0:
            window = [mix.telemetry() for _ in range(min(WINDOW, remaining))]
            remaining -= len(window)
            for text, _, _ in window:
                client.send_text(text)
            sent += len(window)
            for _, kind, good in window:
                reply = client.receive_reply(30)
                answered += 1
                if _reply_kind(reply) != kind:
                    mismatched += 1
                elif good is not None and reply != reference[good]:
                    wrong += 1
        client.send_text('42["telemetry",null]')  # a sentinel: an extra (double) answer would arrive before it
        if client.receive_reply(30) is not None:
            mismatched += 1
        tally.add(sent=sent + 1, answered=answered + 1, mismatched=mismatched, wrong_commands=wrong)
        if rng.random() < 0.35:
            client._sock.sendall(rng.choice(PROTOCOL_ERRORS))  # raw: a frame no simulator sends
            try:
                client.receive_reply(30)
            except ConnectionClosed:
                tally.add(closed_on_error=1)


def campaign(url: str, frames: list[Frame], reference: list[SteerCommand], total: int, seed: int,
             threads: int = 2) -> Tally:
    tally = Tally()
    per_thread = total // threads

    def worker(k: int) -> None:
        rng = random.Random(seed * 1000 + k)
        mix = Mix(frames, rng)
        done = 0
        while done < per_thread:
            batch = min(rng.randrange(50, 300), per_thread - done)
            try:
                fuzz_connection(url, mix, reference, batch, tally, rng)
            except (ConnectionClosed, TimeoutError, OSError) as exc:
                tally.add(lost=1)
                log.warning("a fuzz connection failed: %s", exc)
            done += batch

    pool = [threading.Thread(target=worker, args=(k,)) for k in range(threads)]
    for t in pool:
        t.start()
    for t in pool:
        t.join()
    return tally


# -- phase 2 -------------------------------------------------------------------------------------------
def _healthy(url: str, payload: dict[str, str], n: int, duration: float, out: Any) -> None:
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


def _flooder(url: str, stop: Any, nice: bool) -> None:
    """Writes manual-mode telemetries without ever reading; reconnects whenever it is dropped."""
    if nice:
        _step_aside()
    while not stop.is_set():
        try:
            client = UnityWireClient(url)
            client.connect()
            client._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            blob = client.telemetry_frame(None) * 2000
            while not stop.is_set():
                client._sock.sendall(blob)
        except (OSError, ConnectionError):
            time.sleep(0.05)


def _fuzzer(url: str, frames: list[Frame], reference: list[SteerCommand], stop: Any, nice: bool, seed: int) -> None:
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


def fairness(url: str, frames: list[Frame], reference: list[SteerCommand], healthy: int, duration: float,
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
def _rss_mib(pid: int | None) -> float | None:
    if pid is None:
        return None
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return round(int(line.split()[1]) / 1024, 1)
    except OSError:
        return None
    return None


def _fds(pid: int | None) -> int | None:
    try:
        return len(os.listdir(f"/proc/{pid}/fd")) if pid is not None else None
    except OSError:
        return None


def _settled_fds(pid: int | None, baseline: int | None, timeout: float = 10.0) -> int | None:
    """Open fds once closed connections are gone (the server closes them within a moment)."""
    deadline = time.monotonic() + timeout
    fds = _fds(pid)
    while fds is not None and baseline is not None and fds > baseline and time.monotonic() < deadline:
        time.sleep(0.2)
        fds = _fds(pid)
    return fds


def run(args: argparse.Namespace) -> int:
    frames = log_frames(DEFAULT_LOG) if DEFAULT_LOG.is_dir() else synthetic_frames(16, seed=args.seed)
    frames = frames[:16]
    server: ServerProcess | None = None
    pid = args.pid
    if args.server:
        url = args.server
    else:
        from drive_server.models_dir import default_model_path

        server = ServerProcess(args.model or default_model_path(), ["--log-every", "0", *args.server_args.split()])
        url = server.start()
        pid = server._proc.pid if server._proc else None  # ServerProcess keeps its child private
    try:
        with UnityWireClient(url) as client:  # what a clean connection answers to each good frame
            reference = [client.exchange(f.payload())[0] for f in frames]
        rss0, fds0 = _rss_mib(pid), _fds(pid)
        print(f"server {url}: RSS {rss0} MiB, {fds0} open fds before the campaign")
        t0 = time.perf_counter()
        tally = campaign(url, frames, reference, args.telemetries, args.seed)
        wall = time.perf_counter() - t0
        alive = server is None or (server._proc is not None and server._proc.poll() is None)
        rss1, fds1 = _rss_mib(pid), _settled_fds(pid, fds0)
        print(f"campaign: {tally.sent} telemetries over {tally.connections} connections in {wall:.1f} s "
              f"({tally.sent / wall:.0f}/s); answered {tally.answered}; double or missing answers {tally.mismatched}; "
              f"wrong commands on good frames {tally.wrong_commands}; connections closed on a protocol error "
              f"{tally.closed_on_error}; connections lost {tally.lost}; crashes {0 if alive else 1}")
        if rss0 is not None:
            print(f"server after the campaign: RSS {rss1} MiB ({rss1 - rss0:+.1f} MiB), {fds1} open fds "
                  f"(baseline {fds0})")
        nice = not args.no_nice
        alone, beside = fairness(url, frames, reference, args.healthy, args.duration, nice, args.seed)
        print(f"{args.healthy} healthy 30 Hz clients alone: round trip p50 {alone['p50_ms']} ms, p99 "
              f"{alone['p99_ms']} ms, max {alone['max_ms']} ms ({alone['frames']} frames)")
        print(f"{args.healthy} healthy 30 Hz clients beside 2 misbehaving ones{'' if nice else ' (not niced)'}: "
              f"round trip p50 {beside['p50_ms']} ms, p99 {beside['p99_ms']} ms, max {beside['max_ms']} ms "
              f"({beside['frames']} frames; the two conditions interleaved every 2 s)")
        rss2, fds2 = _rss_mib(pid), _settled_fds(pid, fds0)
        if rss0 is not None:
            print(f"server after everything: RSS {rss2} MiB ({rss2 - rss0:+.1f} MiB), {fds2} open fds "
                  f"(baseline {fds0})")
        alive = server is None or (server._proc is not None and server._proc.poll() is None)
        result = {"url": url, "campaign": {k: v for k, v in vars(tally).items() if k != "lock"} | {
                      "wall_s": round(wall, 1), "crashes": 0 if alive else 1},
                  "rss_mib": {"before": rss0, "after_campaign": rss1, "after_all": rss2},
                  "fds": {"before": fds0, "after_campaign": fds1, "after_all": fds2},
                  "healthy_alone": alone, "healthy_beside_misbehaving": beside, "misbehaving_niced": nice}
        if args.json:
            args.json.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
        ok = alive and tally.mismatched == 0 and tally.wrong_commands == 0 and tally.lost == 0
        return 0 if ok else 1
    finally:
        if server is not None:
            server.stop()
            text = server.log()
            tail = [ln for ln in text.splitlines() if "stopped:" in ln]
            if tail:
                print("server:", tail[-1].split("stopped: ", 1)[1])
            print(f"server log: {len(text.encode()):,} bytes, {text.count(chr(10)):,} lines, "
                  f"{text.count('Traceback')} tracebacks")
            server.cleanup()
