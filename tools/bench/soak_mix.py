"""What ``rbc soak`` sends: the steady mix of clients, each counting what it sent and got back.

``clients`` Unity-wire simulators in closed loop on real frames, one client that reconnects in a loop,
one that upgrades and then says nothing (until the server drops it, then again), a trickle of malformed
telemetries between good ones, and the live view's event stream. Exactly-once is checked the way
``rbc fuzz`` checks it: every 50 frames (and at the end) a simulator sends a null telemetry, which the
server answers with ``manual``; a ``steer`` read before that ``manual`` is an extra answer
(``double_answered``), and a telemetry with no reply within the client timeout is ``unanswered`` (the
client then reconnects). :mod:`tools.bench.soak` runs the mix and measures the server beside it.
"""

from __future__ import annotations

import threading
import time
import urllib.request
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from functools import partial

from protocol import SteerCommand
from tools.wire.frames import SourceFrame
from tools.wire.unity_client import ConnectionClosed, UnityWireClient

#: A null telemetry: the server answers it with ``manual`` (the sentinel of the exactly-once check).
SENTINEL = '42["telemetry",null]'
#: Frames between two sentinels on a driving client.
SENTINEL_EVERY = 50
#: Seconds a telemetry may wait for its reply before it counts as unanswered.
REPLY_TIMEOUT_S = 5.0
#: At most this many client errors are kept for the record (the counts keep the rest).
MAX_ERRORS = 20
#: What a client that lost its connection catches before it connects again.
LOST = (ConnectionClosed, OSError, TimeoutError)


@dataclass
class Tally:
    """What one client (or all of them) sent and got back; guarded by the owner's lock when shared."""

    telemetries: int = 0
    answered: int = 0
    unanswered: int = 0
    double_answered: int = 0
    wrong_kind: int = 0  # a manual where a steer was due
    disconnects: int = 0  # the server closed a driving client's connection (it reconnects)
    malformed: int = 0
    reconnects: int = 0
    idle_sessions: int = 0
    live_events: int = 0
    errors: list[str] = field(default_factory=list)

    def add(self, other: Tally) -> None:
        for name, value in asdict(other).items():
            if name == "errors":
                self.errors.extend(other.errors[:MAX_ERRORS - len(self.errors)])
            else:
                setattr(self, name, getattr(self, name) + value)


class SoakMix:
    """The clients of one soak against the server at ``url``; ``threads(rates)`` starts none of them yet."""

    def __init__(self, url: str, frames: list[SourceFrame], malformed_every_s: float = 1.0,
                 reconnect_every_s: float = 0.5) -> None:
        self.url = url
        self.payloads = [f.payload() for f in frames]
        self.malformed_every_s, self.reconnect_every_s = malformed_every_s, reconnect_every_s
        self.stop = threading.Event()
        self.lock = threading.Lock()
        self.tally = Tally()
        # per driving client, (seconds since start, round trip s) in time order; appended by its thread only
        self.rtts: list[list[tuple[float, float]]] = []
        self.t0 = 0.0

    def threads(self, rates_hz: list[float]) -> list[threading.Thread]:
        bodies: list[Callable[[Tally], None]] = [
            partial(self._driving, rate_hz=hz, offset=7 * n) for n, hz in enumerate(rates_hz)]
        bodies += [self._reconnecting, self._idle, self._malformed, self._live_view]
        return [threading.Thread(target=self._counted, args=(body,), daemon=True) for body in bodies]

    def _counted(self, body: Callable[[Tally], None]) -> None:
        """Run one client with its own tally, merged into the soak's when it ends."""
        tally = Tally()
        try:
            body(tally)
        finally:
            with self.lock:
                self.tally.add(tally)

    # -- the exchanges ----------------------------------------------------------------------------
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

    def _exchange(self, client: UnityWireClient, payload: Mapping[str, object] | None, tally: Tally) -> float:
        """One telemetry that must be answered with a steer (a good frame, or a bad one's fallback)."""
        tally.telemetries += 1
        try:
            reply, rtt = client.exchange(payload)
        except TimeoutError:
            tally.unanswered += 1
            raise
        tally.answered += 1
        if not isinstance(reply, SteerCommand):
            tally.wrong_kind += 1
        return rtt

    # -- the clients ------------------------------------------------------------------------------
    def _driving(self, tally: Tally, rate_hz: float, offset: int) -> None:
        """A simulator in closed loop at ``rate_hz`` on the real frames (from frame ``offset``)."""
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
                        rtts.append((sent, self._exchange(client, self.payloads[i % len(self.payloads)], tally)))
                        i += 1
                        if i % SENTINEL_EVERY == 0:
                            self._sentinel(client, tally)
                        t_next += period
                        time.sleep(max(0.0, t_next - time.perf_counter()))
                    self._sentinel(client, tally)
            except LOST as exc:
                tally.disconnects += 1
                tally.errors.append(f"driving client: {exc}")
                self.stop.wait(0.2)

    def _reconnecting(self, tally: Tally) -> None:
        while not self.stop.is_set():
            try:
                with UnityWireClient(self.url, timeout=REPLY_TIMEOUT_S) as client:
                    for k in range(2):
                        self._exchange(client, self.payloads[k], tally)
                tally.reconnects += 1
            except LOST as exc:
                tally.errors.append(f"reconnecting client: {exc}")
            self.stop.wait(self.reconnect_every_s)

    def _idle(self, tally: Tally) -> None:
        """Upgrade, then send nothing (pings read, never answered) until the server drops the connection
        (its ping timeout) or the soak ends; then again."""
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

    def _malformed(self, tally: Tally) -> None:
        """Between good frames, now and then a telemetry no simulator would send; each must be answered."""
        good = self.payloads[0]
        bad = [dict(good, image="not base64 at all"), dict(good, speed="abc"),
               {k: v for k, v in good.items() if k != "image"}, dict(good, steering_angle="1_000")]
        k = 0
        while not self.stop.is_set():
            try:
                with UnityWireClient(self.url, timeout=REPLY_TIMEOUT_S) as client:
                    while not self.stop.is_set():
                        self._exchange(client, bad[k % len(bad)], tally)  # answered with the fallback
                        tally.malformed += 1
                        k += 1
                        for _ in range(4):  # good frames again (the fallback holds, then the car drives on)
                            self.stop.wait(self.malformed_every_s / 5)
                            self._exchange(client, good, tally)
            except LOST as exc:
                tally.disconnects += 1
                tally.errors.append(f"malformed client: {exc}")
                self.stop.wait(0.2)

    def _live_view(self, tally: Tally) -> None:
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
