"""Transport tuning for python-engineio's eventlet WebSocket: remove costs that need not be there.

Why: eventlet unmasks every client frame one byte at a time in Python. A Unity telemetry frame is
~21 KB, so that alone costs several milliseconds per frame, more than decoding and running the network.
Here it is replaced by a numpy XOR over 32-bit words.

The change is narrow and checked (the reaches into eventlet and engine.io are in
:mod:`drive_server.wire.patches.eventlet_engineio`):
- only OUR server's engine.io instance gets the tuned WebSocket class (other servers in the process keep
  the stock one);
- the fast unmask is set on each WebSocket INSTANCE; eventlet's class is not modified;
- it is applied only to eventlet versions whose frame parser was checked to unmask the way the
  replacement expects (``supported_eventlet``); otherwise the server logs and runs stock.

Also sets TCP_NODELAY on the upgraded connection: the simulator keeps two frames in flight, so the
second reply can be ready while the first is still unacknowledged, and Nagle's algorithm would then
hold it until the client's delayed ACK (measured: occasional 40 ms stalls without it, none with it).
"""

from __future__ import annotations

import contextlib
import logging
import socket
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from drive_server.wire.patches import eventlet_engineio as wire
from protocol.websocket import xor_mask

if TYPE_CHECKING:
    from wsgiref.types import WSGIEnvironment

    from drive_server.wire.patches.eventlet_engineio import EngineServer, EventletWebSocket

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TransportTuning:
    """Which transport optimisations to apply (all on by default; off = stock python-socketio)."""

    fast_unmask: bool = True
    tcp_nodelay: bool = True
    direct_reply: bool = True  # server: hand the encoded reply to engine.io instead of socketio.emit

    @classmethod
    def stock(cls) -> TransportTuning:
        return cls(fast_unmask=False, tcp_nodelay=False, direct_reply=False)


def fast_apply_mask(data: bytes, mask: bytes | bytearray, length: int | None = None, offset: int = 0) -> bytes:
    """Drop-in for eventlet's byte-by-byte unmask (same signature), vectorised."""
    return xor_mask(data, mask, length, offset)


def supported_eventlet(version: str | None = None) -> tuple[bool, str]:
    """Whether the fast-unmask patch applies to this eventlet, and why not if it does not."""
    return wire.fast_unmask_supported(version)


def tuned_websocket_class(base: type, tuning: TransportTuning) -> type:
    """A subclass of engine.io's eventlet ``WebSocketWSGI`` that applies ``tuning`` per connection."""

    def on_request(environ: WSGIEnvironment) -> None:
        if tuning.tcp_nodelay and "eventlet.input" in environ:
            with contextlib.suppress(OSError, AttributeError):
                environ["eventlet.input"].get_socket().setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def on_upgrade(environ: WSGIEnvironment, ws: EventletWebSocket) -> None:
        wire.use_unmask(ws, fast_apply_mask)

    return wire.hooked_websocket_class(base, "TunedWebSocketWSGI", on_request=on_request,
                                       on_upgrade=on_upgrade if tuning.fast_unmask else None)


def install(eio_server: EngineServer, tuning: TransportTuning = TransportTuning()) -> TransportTuning:
    """Give ``eio_server`` (an ``engineio.Server`` in eventlet mode) the tuned WebSocket; returns what
    was actually applied."""
    if eio_server.async_mode != "eventlet":
        log.warning("transport tuning needs async_mode 'eventlet', not %r: running stock", eio_server.async_mode)
        return replace(tuning, fast_unmask=False, tcp_nodelay=False)
    if tuning.fast_unmask:
        ok, why = supported_eventlet()
        if not ok:
            log.warning("fast WebSocket unmasking not applied (%s): expect several ms more per frame", why)
            tuning = replace(tuning, fast_unmask=False)
    if tuning.fast_unmask or tuning.tcp_nodelay:
        wire.wrap_websocket_class(eio_server, lambda base: tuned_websocket_class(base, tuning))
    return tuning
