"""The transports' gates: where the limits of :mod:`drive_server.limits` are enforced on the wire.

Connections (header timeout, cap, eviction of half-open ones), long-polling bodies (413 before the body
is read), WebSocket messages (a bound on the whole message while its frames arrive, one message per
connection per turn), and the kernel's send queue of a client that does not read. See the module
docstring of :mod:`drive_server.limits` for what each closes and why.
"""

from __future__ import annotations

import contextlib
import io
import logging
import socket
import struct
import sys
from collections import OrderedDict
from collections.abc import Callable
from time import monotonic
from typing import Any
from urllib.parse import parse_qs

from drive_server.limits import (
    CLOSE_PROTOCOL_ERROR,
    FaultLog,
    WireLimits,
    close_reason,
    packet_problem,
)

if sys.platform.startswith("linux"):
    import fcntl
    import termios

    _TIOCOUTQ: int | None = termios.TIOCOUTQ
else:  # pragma: no cover
    _TIOCOUTQ = None

log = logging.getLogger(__name__)


def limited_message_class(base: type, limit: int, on_too_large: Callable[[int], None]) -> type:
    """eventlet's ``RFC6455WebSocket.Message`` with a bound on the WHOLE message, fragments included.

    eventlet checks each frame's length, then joins any number of continuation frames (256 MiB in 200 KiB
    fragments used to be buffered whole). ``push`` is called for every received chunk, so the bound holds
    while the message arrives, at most one recv chunk past it.
    """
    from eventlet.websocket import FailedConnectionError

    class LimitedMessage(base):  # type: ignore[misc, valid-type]
        size = 0

        def push(self, data: bytes, final: bool = False) -> None:
            self.size += len(data)
            if self.size > limit:
                on_too_large(self.size)
                raise FailedConnectionError(1009, f"message larger than {limit} bytes")
            super().push(data, final=final)

    return LimitedMessage


def guard_websocket(ws: Any, limits: WireLimits, faults: FaultLog, peer: str, heard: list[float]) -> None:
    """Apply the per-connection limits to one eventlet ``RFC6455WebSocket`` (instance attributes only);
    ``heard[0]`` becomes the time of its latest message (what the connection cap's idle eviction reads)."""
    ws.Message = limited_message_class(
        type(ws).Message, limits.max_message_bytes,
        lambda size: faults.report("message_too_large", "%s: WebSocket message of %d+ bytes (limit %d): closed",
                                   peer, size, limits.max_message_bytes))
    import eventlet

    stock_wait = ws.wait

    def wait() -> Any:
        # one message per connection per turn of the event loop: a client whose socket always has data
        # (a flood) must not keep the loop from the other clients' readers and writers
        eventlet.sleep(0)
        data = stock_wait()
        if data is None:
            return None
        heard[0] = monotonic()
        problem = packet_problem(data)
        if problem is not None:
            faults.report("protocol_error", "%s: protocol error (%s): connection closed", peer, problem)
            ws._send_closing_frame(True, close_data=(CLOSE_PROTOCOL_ERROR, close_reason(problem)))
            return None  # engine.io then ends the session as if the client had closed it
        return data

    ws.wait = wait


def websocket_gate_supported() -> tuple[bool, str]:
    """Whether eventlet's frame parser builds messages through ``self.Message`` (the total-size bound)."""
    import inspect

    from eventlet.websocket import RFC6455WebSocket

    try:
        source = inspect.getsource(RFC6455WebSocket._recv_frame)
    except (OSError, TypeError):
        return False, "cannot read RFC6455WebSocket._recv_frame"
    if "self.Message(" not in source or not hasattr(RFC6455WebSocket.Message, "push"):
        return False, "RFC6455WebSocket._recv_frame does not build messages through self.Message"
    return True, ""


def limited_websocket_class(base: type, limiter: ConnectionLimiter) -> type:
    """A subclass of engine.io's eventlet ``WebSocketWSGI`` that guards every connection it upgrades and
    tells ``limiter`` when each last sent something."""
    from eventlet.websocket import RFC6455WebSocket

    limits, faults = limiter.limits, limiter.faults
    ok, why = websocket_gate_supported()
    if not ok:
        log.warning("WebSocket messages bounded only after reassembly (%s)", why)

    class LimitedWebSocketWSGI(base):  # type: ignore[misc, valid-type]
        def __call__(self, environ: dict[str, Any], start_response: Callable) -> Any:
            try:
                return super().__call__(environ, start_response)  # the whole WebSocket session
            finally:
                ws = environ.get("rbc.websocket")
                if ws is not None:
                    limiter.upgraded.pop(id(ws), None)

        def _handle_hybi_request(self, environ: dict[str, Any]) -> Any:
            ws = super()._handle_hybi_request(environ)
            if isinstance(ws, RFC6455WebSocket):
                peer = f"{environ.get('REMOTE_ADDR', '?')}:{environ.get('REMOTE_PORT', '?')}"
                heard = [monotonic()]  # the upgrade counts as hearing from it
                limiter.upgraded[id(ws)] = (ws.socket, heard)
                if ok:
                    guard_websocket(ws, limits, faults, peer, heard)
                environ["rbc.websocket"] = ws  # lets the server close this connection with a close frame
            return ws

    return LimitedWebSocketWSGI


def _raw_response(environ: dict[str, Any], status: str, body: bytes) -> list[bytes]:
    """Write a complete response with ``Connection: close`` directly and tell eventlet it is handled.

    Why not ``start_response``: after a normal response eventlet reads and discards the unread request
    body to keep the connection alive, which waits forever on a client that sent only the header.
    ``WSGI_LOCAL.already_handled`` (what eventlet's own WebSocket uses) makes it close the connection.
    """
    import eventlet.wsgi

    sock = environ["eventlet.input"].get_socket()
    with contextlib.suppress(OSError):
        sock.sendall(f"HTTP/1.1 {status}\r\nContent-Type: text/plain\r\nContent-Length: {len(body)}\r\n"
                     "Connection: close\r\n\r\n".encode("latin-1") + body)
    eventlet.wsgi.WSGI_LOCAL.already_handled = True
    return []


def polling_gate(app: Callable, eio_server: Any, limits: WireLimits, faults: FaultLog) -> Callable:
    """WSGI middleware: refuse an Engine.IO long-polling POST before engine.io reads it.

    Oversized (from Content-Length alone) -> 413, chunked -> 411, body not sent within the header
    timeout or packets that fail ``packet_problem`` -> 400; each time the session is
    closed without waiting and the connection is freed.
    """

    import eventlet

    def close_session(environ: dict[str, Any]) -> None:
        sid = parse_qs(environ.get("QUERY_STRING", "")).get("sid", [None])[0]
        session = eio_server.sockets.get(sid) if sid else None
        if session is not None and not session.closed:
            session.close(wait=False, abort=False)  # wait=True would wait for a poll that may never come

    def gate(environ: dict[str, Any], start_response: Callable) -> Any:
        if environ.get("REQUEST_METHOD") != "POST" or "eventlet.input" not in environ:
            return app(environ, start_response)
        peer = f"{environ.get('REMOTE_ADDR', '?')}:{environ.get('REMOTE_PORT', '?')}"
        if "chunked" in environ.get("HTTP_TRANSFER_ENCODING", "").lower():
            faults.report("protocol_error", "%s: chunked long-polling POST refused (411)", peer)
            close_session(environ)
            return _raw_response(environ, "411 Length Required", b"Content-Length required")
        try:
            length = int(environ.get("CONTENT_LENGTH") or 0)
        except ValueError:
            length = -1
        if not 0 <= length <= limits.max_message_bytes:
            faults.report("message_too_large", "%s: long-polling POST of %s bytes (limit %d): refused (413)",
                          peer, environ.get("CONTENT_LENGTH"), limits.max_message_bytes)
            close_session(environ)
            return _raw_response(environ, "413 Payload Too Large", b"payload too large")
        try:
            with eventlet.Timeout(limits.header_timeout_s):
                body = environ["wsgi.input"].read(length)
        except eventlet.Timeout:
            faults.report("header_timeout", "%s: long-polling body not sent within %.0f s: closed",
                          peer, limits.header_timeout_s)
            close_session(environ)
            return _raw_response(environ, "408 Request Timeout", b"")
        text = body.decode("utf-8", errors="replace")
        problem = next(filter(None, map(packet_problem, text.split("\x1e"))), None)
        if problem is not None:
            faults.report("protocol_error", "%s: protocol error (%s): session closed", peer, problem)
            close_session(environ)
            return _raw_response(environ, "400 Bad Request", problem.encode())
        environ["wsgi.input"] = io.BytesIO(body)
        return app(environ, start_response)

    return gate


class ConnectionLimiter:
    """Counts the open connections and remembers which are still sending their headers and when each
    upgraded WebSocket last sent something."""

    def __init__(self, limits: WireLimits, faults: FaultLog) -> None:
        self.limits = limits
        self.faults = faults
        self.open = 0
        self.waiting: OrderedDict[int, Any] = OrderedDict()  # id(protocol) -> socket, oldest first
        self.upgraded: dict[int, tuple[Any, list[float]]] = {}  # id(websocket) -> (socket, [last message time])
        self.ended = 0  # connections ended so far (the server collects their garbage when it is quiet)

    def admit(self, peer: str) -> bool:
        """Whether a new connection may be served. At the cap, the oldest connection still sending its
        headers is closed to make room, else the WebSocket silent longest if it has been silent for
        ``idle_evict_s`` (its own greenthread then ends and gives its slot back)."""
        if self.open >= self.limits.max_connections:
            if self.waiting:
                _, sock = self.waiting.popitem(last=False)
                self.faults.report("evicted", "connection limit (%d) reached: closed the oldest connection still "
                                   "sending its headers to admit %s", self.limits.max_connections, peer)
            else:
                sock, silent_s = self._idlest()
                if sock is None:
                    self.faults.report("refused", "connection limit (%d, --max-connections) reached: refused %s",
                                       self.limits.max_connections, peer)
                    return False
                self.faults.report("evicted", "connection limit (%d) reached: closed a WebSocket silent for "
                                   "%.0f s (--idle-evict) to admit %s", self.limits.max_connections, silent_s, peer)
            shutdown_socket(sock)  # its blocked read returns EOF
        self.open += 1
        return True

    def _idlest(self) -> tuple[Any, float]:
        """The socket of the WebSocket silent longest, if past ``idle_evict_s`` (else None), and its silence."""
        if not self.upgraded:
            return None, 0.0
        key, (sock, heard) = min(self.upgraded.items(), key=lambda item: item[1][1][0])
        silent_s = monotonic() - heard[0]
        if silent_s < self.limits.idle_evict_s:
            return None, silent_s
        del self.upgraded[key]  # evicted once: the next newcomer looks at the next idlest
        return sock, silent_s


def protocol_class(limiter: ConnectionLimiter) -> type:
    """eventlet's ``HttpProtocol`` with the connection cap and the header timeout of ``limiter``."""
    import eventlet
    import eventlet.wsgi

    limits, faults = limiter.limits, limiter.faults

    class LimitedProtocol(eventlet.wsgi.HttpProtocol):
        _timer: Any = None

        def handle(self) -> None:
            address = self.client_address
            peer = f"{address[0]}:{address[1]}" if isinstance(address, tuple) else str(address)
            if not limiter.admit(peer):
                with contextlib.suppress(OSError):
                    self.connection.sendall(b"HTTP/1.1 503 Service Unavailable\r\nConnection: close\r\n"
                                            b"Retry-After: 5\r\nContent-Length: 0\r\n\r\n")
                self.close_connection = 1
                return
            try:
                super().handle()
            finally:
                limiter.waiting.pop(id(self), None)
                limiter.open -= 1
                limiter.ended += 1

        def handle_one_request(self) -> None:
            """One request; the request line and headers must arrive within ``header_timeout_s`` (an idle
            keep-alive connection waiting for its next request is closed after that time, too)."""
            limiter.waiting[id(self)] = self.connection
            self._timer = timer = eventlet.Timeout(limits.header_timeout_s)
            try:
                super().handle_one_request()
            except eventlet.Timeout as exc:
                if exc is not timer:
                    raise
                faults.report("header_timeout", "%s: no complete request within %.0f s (--header-timeout): closed",
                              self.client_address[0], limits.header_timeout_s)
                self.close_connection = 1
            except OSError:  # a connection error of one client is no reason for a traceback
                self.close_connection = 1
            finally:
                self._end_header_phase()

        def handle_one_response(self) -> None:
            self._end_header_phase()  # the response (a long poll, a whole WebSocket session) has no deadline
            super().handle_one_response()

        def _end_header_phase(self) -> None:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            limiter.waiting.pop(id(self), None)

    return LimitedProtocol


def unsent_bytes(sock: Any) -> int:
    """Bytes queued in the kernel for ``sock`` and not yet sent or acknowledged (Linux ``SIOCOUTQ``; 0 where
    the platform cannot tell, which leaves the pending-reply queue as the only signal)."""
    if _TIOCOUTQ is None:
        return 0
    try:
        return struct.unpack("i", fcntl.ioctl(sock.fileno(), _TIOCOUTQ, b"\0\0\0\0"))[0]
    except (OSError, ValueError):
        return 0


def shutdown_socket(sock: Any, reset: bool = False) -> None:
    """Close a connection at once, both ways; its blocked reader sees EOF and its writer an error.

    ``reset`` (a client that does not read its replies): ``SO_LINGER`` 0 makes the final close send a
    TCP reset and drop the unsent replies. A plain close would leave the kernel holding them behind a
    FIN the client never reads up to, and the client, blocked writing into a window that never opens,
    would not learn about it until its own timeout (no close frame either: it could not be sent).
    """
    with contextlib.suppress(OSError):
        if reset:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        sock.shutdown(socket.SHUT_RDWR)
