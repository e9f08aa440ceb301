"""Transport tuning for python-engineio's eventlet WebSocket: remove costs that need not be there.

Why: eventlet's ``RFC6455WebSocket._apply_mask`` unmasks every client frame one byte at a time in
Python. A Unity telemetry frame is ~21 KB, so that alone costs several milliseconds per frame, more
than decoding and running the network. Here it is replaced by a numpy XOR over 32-bit words.

The change is narrow and checked:
- only OUR server's engine.io instance gets the tuned WebSocket class (``install`` copies its
  async-driver table; other servers in the process keep the stock one);
- the fast unmask is set on each WebSocket INSTANCE, shadowing the static method; eventlet's class is
  not modified;
- it is applied only to eventlet versions whose frame parser was checked to call ``self._apply_mask``
  with the signature used here (``supported_eventlet``); otherwise the server logs and runs stock.

Also sets TCP_NODELAY on the upgraded connection: the simulator keeps two frames in flight, so the
second reply can be ready while the first is still unacknowledged, and Nagle's algorithm would then
hold it until the client's delayed ACK (measured: occasional 40 ms stalls without it, none with it).
"""

from __future__ import annotations

import contextlib
import inspect
import logging
import socket
from dataclasses import dataclass, replace
from typing import Any

from protocol.websocket import xor_mask

log = logging.getLogger(__name__)

#: eventlet versions the patch is applied to (inclusive): the project's floor up to the newest one read and
#: tested (0.41). A newer eventlet runs stock until someone checks its frame parser and raises the bound.
TESTED_EVENTLET = ((0, 35), (0, 41))


@dataclass(frozen=True)
class TransportTuning:
    """Which transport optimisations to apply (all on by default; off = stock python-socketio)."""

    fast_unmask: bool = True
    tcp_nodelay: bool = True
    direct_reply: bool = True  # server: hand the encoded reply to engine.io instead of socketio.emit

    @classmethod
    def stock(cls) -> TransportTuning:
        return cls(fast_unmask=False, tcp_nodelay=False, direct_reply=False)


def fast_apply_mask(data: bytes, mask: Any, length: int | None = None, offset: int = 0) -> bytes:
    """Drop-in for ``eventlet.websocket.RFC6455WebSocket._apply_mask`` (same signature), vectorised."""
    return xor_mask(data, mask, length, offset)


def _version_tuple(version: str) -> tuple[int, int]:
    parts = version.split(".")
    try:
        return int(parts[0]), int(parts[1])
    except (IndexError, ValueError):
        return (-1, -1)


def supported_eventlet(version: str | None = None) -> tuple[bool, str]:
    """Whether the fast-unmask patch applies to this eventlet, and why not if it does not."""
    import eventlet
    from eventlet.websocket import RFC6455WebSocket

    version = eventlet.__version__ if version is None else version
    lo, hi = TESTED_EVENTLET
    if not lo <= _version_tuple(version) <= hi:
        return False, f"eventlet {version} is outside the tested range {lo}..{hi}"
    original = inspect.getattr_static(RFC6455WebSocket, "_apply_mask", None)
    if not isinstance(original, staticmethod):
        return False, "RFC6455WebSocket._apply_mask is not a static method"
    if list(inspect.signature(original.__func__).parameters) != ["data", "mask", "length", "offset"]:
        return False, "RFC6455WebSocket._apply_mask has an unexpected signature"
    try:
        source = inspect.getsource(RFC6455WebSocket._recv_frame)
    except (OSError, TypeError):
        return False, "cannot read RFC6455WebSocket._recv_frame to check it"
    if "self._apply_mask(" not in source:
        return False, "RFC6455WebSocket._recv_frame does not unmask through self._apply_mask"
    return True, ""


def tuned_websocket_class(base: type, tuning: TransportTuning) -> type:
    """A subclass of engine.io's eventlet ``WebSocketWSGI`` that applies ``tuning`` per connection."""
    from eventlet.websocket import RFC6455WebSocket

    class TunedWebSocketWSGI(base):  # type: ignore[misc, valid-type]
        def __call__(self, environ: dict[str, Any], start_response: Any) -> Any:
            if tuning.tcp_nodelay and "eventlet.input" in environ:
                with contextlib.suppress(OSError, AttributeError):
                    environ["eventlet.input"].get_socket().setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return super().__call__(environ, start_response)

        def _handle_hybi_request(self, environ: dict[str, Any]) -> Any:
            ws = super()._handle_hybi_request(environ)
            if tuning.fast_unmask and isinstance(ws, RFC6455WebSocket):
                ws._apply_mask = fast_apply_mask  # instance attribute shadows the byte-by-byte staticmethod
            return ws

    return TunedWebSocketWSGI


def install(eio_server: Any, tuning: TransportTuning = TransportTuning()) -> TransportTuning:
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
        table = dict(eio_server._async)  # a copy: the driver's module-level table stays stock
        table["websocket"] = tuned_websocket_class(table["websocket"], tuning)
        eio_server._async = table
    return tuning
