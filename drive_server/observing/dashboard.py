"""The live view: a read-only page, on the simulator's own port, of what every connected simulator sees and does.

Why Server-Sent Events and no client library: the browser's built-in ``EventSource`` needs nothing
vendored, and one push per tick to each viewer costs the event loop less than viewers polling.

The drive loop does not pay for it. The server stores a reference to the latest answered frame of a
client (one attribute assignment, :class:`LiveFrame`); everything else happens in one ticker
greenthread that runs only while a viewer is connected: it builds one snapshot per tick (frames at
``rate_hz``, latency percentiles over the recent frames at ``stats_hz``) and offers it to every
viewer's queue of two. A viewer whose queue is full (slow or stuck) is dropped, never waited for.
Read-only: only GET of the page, its two files and the event stream; nothing can be changed from it.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from importlib import resources
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from wsgiref.types import StartResponse, WSGIEnvironment

    from drive_server.serving.client_monitor import MonitorReading

log = logging.getLogger(__name__)

#: Page files served from drive_server/observing/static, with their content types.
STATIC = {"/": ("dashboard.html", "text/html; charset=utf-8"),
          "/dashboard.js": ("dashboard.js", "text/javascript; charset=utf-8"),
          "/dashboard.css": ("dashboard.css", "text/css; charset=utf-8")}
EVENTS_PATH = "/events"
#: Recent frames the latency percentiles of the page are computed over (about 20 s at 15 Hz).
RECENT_FRAMES = 300


@dataclass(frozen=True, slots=True)
class LiveFrame:
    """The latest answered telemetry of one client: what the page shows for it."""

    t: float  # time.perf_counter() when it was answered
    image_b64: str  # the JPEG as the simulator sent it (forwarded as is)
    steering: float  # the model's prediction, -1..1 (x steer limit = degrees)
    throttle: float  # the command sent, -1..1 (< 0 brakes)
    speed: float  # the telemetry speed, in the server's telemetry unit
    fallback: bool  # the command came from the fallback policy (held or stopped), not the model
    monitor: MonitorReading | None = None  # the monitor's reading of this frame, if any


class ViewerQueue(Protocol):
    """One viewer's bounded queue of snapshots (JSON bytes; None ends its stream): eventlet's ``LightQueue``."""

    def get(self) -> bytes | None: ...

    def get_nowait(self) -> bytes | None: ...

    def put_nowait(self, item: bytes | None) -> None: ...

    def full(self) -> bool: ...


@dataclass(frozen=True)
class DashboardConfig:
    rate_hz: float = 10.0  # snapshots per second to each viewer (the page never needs more)
    stats_hz: float = 2.0  # latency percentiles recomputed this often
    max_viewers: int = 8
    queue: int = 2  # snapshots waiting for a viewer before it counts as stuck and is dropped


class Dashboard:
    """Serves the page and pushes snapshots; ``snapshot()`` is the server's view of its clients."""

    def __init__(self, snapshot: Callable[[bool], dict[str, object]], sleep: Callable[[float], None],
                 spawn: Callable[[Callable[[], None]], object], make_queue: Callable[[int], ViewerQueue],
                 config: DashboardConfig = DashboardConfig()) -> None:
        self._snapshot, self._sleep, self._spawn, self._make_queue = snapshot, sleep, spawn, make_queue
        self.config = config
        self._viewers: list[ViewerQueue] = []
        self._ticker: object = None  # the ticker's greenthread while it runs
        self.dropped = 0  # viewers dropped for not keeping up
        self.served = 0  # viewers connected so far
        self._files = {path: (resources.files("drive_server.observing").joinpath("static", name).read_bytes(), kind)
                       for path, (name, kind) in STATIC.items()}

    @property
    def viewers(self) -> int:
        return len(self._viewers)

    # -- WSGI ------------------------------------------------------------------------------------
    def wsgi(self, environ: WSGIEnvironment, start_response: StartResponse) -> Iterable[bytes]:
        """Everything that is not ``/socket.io/``: the page, its files, the event stream; else 404/405."""
        path = environ.get("PATH_INFO", "/")
        if environ.get("REQUEST_METHOD", "GET") not in ("GET", "HEAD"):
            return self._plain(start_response, "405 Method Not Allowed", "the dashboard is read-only\n",
                               [("Allow", "GET, HEAD")])
        if path in self._files:
            body, kind = self._files[path]
            start_response("200 OK", [("Content-Type", kind), ("Content-Length", str(len(body))),
                                      ("Cache-Control", "no-cache"), ("X-Content-Type-Options", "nosniff")])
            return [body]
        if path == EVENTS_PATH:
            return self._events(start_response)
        return self._plain(start_response, "404 Not Found", "not found: the dashboard is at /\n")

    @staticmethod
    def _plain(start_response: StartResponse, status: str, text: str,
               headers: list[tuple[str, str]] | None = None) -> list[bytes]:
        body = text.encode()
        start_response(status, [("Content-Type", "text/plain; charset=utf-8"), ("Content-Length", str(len(body))),
                                *(headers or [])])
        return [body]

    def _events(self, start_response: StartResponse) -> Iterable[bytes]:
        if len(self._viewers) >= self.config.max_viewers:
            return self._plain(start_response, "503 Service Unavailable",
                               f"{self.config.max_viewers} viewers already watch this server\n")
        queue = self._make_queue(self.config.queue)
        self._viewers.append(queue)
        self.served += 1
        log.info("dashboard viewer %d connected (%d watching)", self.served, len(self._viewers))
        if self._ticker is None:
            self._ticker = self._spawn(self._tick)
        start_response("200 OK", [("Content-Type", "text/event-stream"), ("Cache-Control", "no-cache"),
                                  ("X-Accel-Buffering", "no")])
        return self._stream(queue)

    def _stream(self, queue: ViewerQueue) -> Iterator[bytes]:
        try:
            yield b"retry: 1000\n\n"
            while True:
                message = queue.get()
                if message is None:  # dropped by the ticker: end this response
                    return
                yield b"data: " + message + b"\n\n"
        finally:
            self._forget(queue)

    def _forget(self, queue: ViewerQueue) -> None:
        if queue in self._viewers:
            self._viewers.remove(queue)

    # -- the ticker ------------------------------------------------------------------------------
    def _tick(self) -> None:
        period, stats_every = 1.0 / self.config.rate_hz, max(1, round(self.config.rate_hz / self.config.stats_hz))
        tick = 0
        try:
            while self._viewers:
                started = time.perf_counter()
                message = json.dumps(self._snapshot(tick % stats_every == 0), separators=(",", ":")).encode()
                for queue in list(self._viewers):
                    if queue.full():  # not reading: dropped, never waited for
                        self._forget(queue)
                        self.dropped += 1
                        log.info("dashboard viewer dropped: it did not keep up (%d watching)", len(self._viewers))
                        _offer_end(queue)
                    else:
                        queue.put_nowait(message)
                tick += 1
                self._sleep(max(0.0, period - (time.perf_counter() - started)))
        finally:
            self._ticker = None


def _offer_end(queue: ViewerQueue) -> None:
    """Tell a dropped viewer's stream to end, if there is room (a stuck one is ended by its socket)."""
    try:
        queue.get_nowait()  # make room: the pending snapshot is of no use any more
        queue.put_nowait(None)
    except Exception:  # eventlet's queue raises its own Empty/Full
        pass
