"""The transports' gates: where the limits of :mod:`drive_server.wire.limits` are enforced on messages.

Long-polling bodies (413 before the body is read) and WebSocket messages (a bound on the whole message
while its frames arrive, one message per connection per turn, the time of each connection's latest
message). The connections themselves (cap, header timeout, eviction) are :mod:`drive_server.wire.connections`.
See the module docstring of :mod:`drive_server.wire.limits` for what each closes and why.
"""

from __future__ import annotations

import contextlib
import io
import logging
from collections.abc import Callable, Iterable
from time import monotonic
from typing import TYPE_CHECKING
from urllib.parse import parse_qs

from drive_server.wire.limits import (
    CLOSE_PROTOCOL_ERROR,
    FaultLog,
    WireLimits,
    close_reason,
    packet_problem,
)
from drive_server.wire.patches import eventlet_engineio as wire

if TYPE_CHECKING:
    from wsgiref.types import StartResponse, WSGIApplication, WSGIEnvironment

    from drive_server.wire.connections import ConnectionLimiter
    from drive_server.wire.patches.eventlet_engineio import EngineServer, EventletWebSocket

log = logging.getLogger(__name__)


def limited_message_class(base: type, limit: int, on_too_large: Callable[[int], None]) -> type:
    """eventlet's ``RFC6455WebSocket.Message`` with a bound on the WHOLE message, fragments included.

    eventlet checks each frame's length, then joins any number of continuation frames (256 MiB in 200 KiB
    fragments used to be buffered whole). ``push`` is called for every received chunk, so the bound holds
    while the message arrives, at most one recv chunk past it.
    """
    from eventlet.websocket import FailedConnectionError

    class LimitedMessage(base):  # type: ignore[misc]
        size = 0

        def push(self, data: bytes, final: bool = False) -> None:
            self.size += len(data)
            if self.size > limit:
                on_too_large(self.size)
                raise FailedConnectionError(1009, f"message larger than {limit} bytes")
            super().push(data, final=final)

    return LimitedMessage


def guard_websocket(ws: EventletWebSocket, limits: WireLimits, faults: FaultLog, peer: str, heard: list[float]) -> None:
    """Apply the per-connection limits to one eventlet ``RFC6455WebSocket`` (instance attributes only);
    ``heard[0]`` becomes the time of its latest message (what the connection cap's idle eviction reads)."""
    ws.Message = limited_message_class(
        type(ws).Message, limits.max_message_bytes,
        lambda size: faults.report("message_too_large", "%s: WebSocket message of %d+ bytes (limit %d): closed",
                                   peer, size, limits.max_message_bytes))
    import eventlet

    stock_wait = ws.wait

    def wait() -> str | bytes | None:
        # one message per connection per turn of the event loop: a client whose socket always has data
        # (a flood) must not keep the loop from the other clients' readers and writers
        eventlet.sleep(0)
        data = stock_wait()  # eventlet's RFC6455WebSocket.wait
        if data is None:
            return None
        heard[0] = monotonic()
        problem = packet_problem(data)
        if problem is not None:
            faults.report("protocol_error", "%s: protocol error (%s): connection closed", peer, problem)
            wire.send_close_frame(ws, CLOSE_PROTOCOL_ERROR, close_reason(problem))
            return None  # engine.io then ends the session as if the client had closed it
        return data

    ws.wait = wait


def limited_websocket_class(base: type, limiter: ConnectionLimiter) -> type:
    """A subclass of engine.io's eventlet ``WebSocketWSGI`` that guards every connection it upgrades and
    tells ``limiter`` when each last sent something."""
    limits, faults = limiter.limits, limiter.faults
    ok, why = wire.whole_message_bound_supported()
    if not ok:
        log.warning("WebSocket messages bounded only after reassembly (%s)", why)

    def on_upgrade(environ: WSGIEnvironment, ws: EventletWebSocket) -> None:
        peer = f"{environ.get('REMOTE_ADDR', '?')}:{environ.get('REMOTE_PORT', '?')}"
        heard = [monotonic()]  # the upgrade counts as hearing from it
        limiter.upgraded[id(ws)] = (ws.socket, heard)
        if ok:
            guard_websocket(ws, limits, faults, peer, heard)
        environ["rbc.websocket"] = ws  # lets the server close this connection with a close frame

    def on_end(environ: WSGIEnvironment) -> None:
        ws = environ.get("rbc.websocket")
        if ws is not None:
            limiter.upgraded.pop(id(ws), None)

    return wire.hooked_websocket_class(base, "LimitedWebSocketWSGI", on_upgrade=on_upgrade, on_end=on_end)


def _raw_response(environ: WSGIEnvironment, status: str, body: bytes) -> list[bytes]:
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


def polling_gate(app: WSGIApplication, eio_server: EngineServer, limits: WireLimits,
                 faults: FaultLog) -> WSGIApplication:
    """WSGI middleware: refuse an Engine.IO long-polling POST before engine.io reads it.

    Oversized (from Content-Length alone) -> 413, chunked -> 411, body not sent within the header
    timeout or packets that fail ``packet_problem`` -> 400; each time the session is
    closed without waiting and the connection is freed.
    """

    import eventlet

    def close_session(environ: WSGIEnvironment) -> None:
        sid = parse_qs(environ.get("QUERY_STRING", "")).get("sid", [None])[0]
        session = eio_server.sockets.get(sid) if sid else None
        if session is not None and not session.closed:
            session.close(wait=False, abort=False)  # wait=True would wait for a poll that may never come

    def gate(environ: WSGIEnvironment, start_response: StartResponse) -> Iterable[bytes]:
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
