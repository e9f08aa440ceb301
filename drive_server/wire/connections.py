"""Connections at the socket level: the cap, the header timeout, who is evicted at the cap, and closing at once.

``ConnectionLimiter`` counts open connections, remembers which are still sending their headers and when
each upgraded WebSocket last sent something (:mod:`drive_server.wire.gates` tells it); ``protocol_class``
puts the cap and the header timeout into eventlet's HTTP protocol. At the cap the oldest connection still
sending its headers is closed, else the WebSocket silent longest past ``idle_evict_s``, else the newcomer
is refused with a 503. ``unsent_bytes`` reads the kernel's send queue of a client that does not read.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import sys
from collections import OrderedDict
from time import monotonic

from drive_server.wire.limits import FaultLog, WireLimits
from drive_server.wire.patches import TcpSocket

if sys.platform.startswith("linux"):
    import fcntl
    import termios

    _TIOCOUTQ: int | None = termios.TIOCOUTQ
else:  # pragma: no cover
    _TIOCOUTQ = None


class ConnectionLimiter:
    """Counts the open connections and remembers which are still sending their headers and when each
    upgraded WebSocket last sent something."""

    def __init__(self, limits: WireLimits, faults: FaultLog) -> None:
        self.limits = limits
        self.faults = faults
        self.open = 0
        self.waiting: OrderedDict[int, TcpSocket] = OrderedDict()  # id(protocol) -> socket, oldest first
        self.upgraded: dict[int, tuple[TcpSocket, list[float]]] = {}  # id(websocket) -> (socket, [last message time])
        self.ended = 0  # connections ended so far (the server collects their garbage when it is quiet)

    def admit(self, peer: str) -> bool:
        """Whether a new connection may be served. At the cap, the oldest connection still sending its
        headers is closed to make room, else the WebSocket silent longest if it has been silent for
        ``idle_evict_s`` (its own greenthread then ends and gives its slot back)."""
        if self.open >= self.limits.max_connections:
            sock: TcpSocket | None
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

    def _idlest(self) -> tuple[TcpSocket | None, float]:
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

    class LimitedProtocol(eventlet.wsgi.HttpProtocol):  # type: ignore[misc]  # eventlet has no stubs: its classes are Any
        _timer: eventlet.Timeout | None = None

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


def unsent_bytes(sock: TcpSocket) -> int:
    """Bytes queued in the kernel for ``sock`` and not yet sent or acknowledged (Linux ``SIOCOUTQ``; 0 where
    the platform cannot tell, which leaves the pending-reply queue as the only signal)."""
    if _TIOCOUTQ is None:
        return 0
    try:
        queued: int = struct.unpack("i", fcntl.ioctl(sock.fileno(), _TIOCOUTQ, b"\0\0\0\0"))[0]
    except (OSError, ValueError):
        return 0
    return queued


def shutdown_socket(sock: TcpSocket, reset: bool = False) -> None:
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
