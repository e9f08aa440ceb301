"""A client that behaves exactly like the Unity driving simulator on the wire.

Why a raw-socket client instead of a Socket.IO library: the simulator's own client is unusual
(websocket only, ``User-Agent: websocket-sharp/1.0``, no Origin, never sends the Socket.IO CONNECT
packet ``40``, pings the server itself). Only a client that does exactly that can prove the drive
server copes with it. It is also small and fast (RFC 6455 framing with numpy masking), so it can
drive latency benchmarks without becoming the bottleneck.

Needs only numpy and ``protocol``.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Mapping
from types import TracebackType
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

import numpy as np

from protocol import SteerCommand, parse_steer
from protocol.errors import BadValue
from tools.wire.websocket import OP_BINARY, OP_TEXT, ConnectionClosed, WebSocketConnection, client_frame

if TYPE_CHECKING:
    import socket

log = logging.getLogger(__name__)

#: The Unity client sends its own Engine.IO ping every 25 s (besides answering the server's).
CLIENT_PING_INTERVAL_S = 25.0
_JSON_UNSAFE = ('"', "\\")
_frame = client_frame  # the name the protocol tests use

__all__ = ["CLIENT_PING_INTERVAL_S", "ConnectionClosed", "UnityWireClient"]


def _json_string(text: str) -> str:
    """JSON-quote ``text``. A 20 KB base64 image needs no escaping, and proving that with numpy costs
    ~8 us where ``json.dumps`` (a per-character scan) costs ~50 us. Short strings go to ``json.dumps``."""
    if len(text) > 256 and text.isascii() and not any(c in text for c in _JSON_UNSAFE):
        codes = np.frombuffer(text.encode("ascii"), np.uint8)
        if not len(codes) or (int(codes.min()) >= 0x20 and int(codes.max()) < 0x7F):
            return '"' + text + '"'
    return json.dumps(text)


class UnityWireClient:
    """Socket.IO client imitating the Unity simulator, one closed loop per instance.

    Behaviour copied from the simulator: opens ``ws://HOST:PORT/socket.io/?EIO=4&transport=websocket``
    directly, ``User-Agent: websocket-sharp/1.0``, no Origin, never sends ``40`` (the server must join
    it to ``/`` on its first event), answers a server ping ``2`` with ``3`` and sends its own ping ``2``
    every 25 s (``ping_interval_s``; checked whenever it sends, as this client has no background
    thread), emits only ``telemetry`` with string values (``decimal=","`` imitates a European locale;
    ``None`` is a manual-mode frame) and listens to ``steer``/``manual``.

    Use as a context manager. ``exchange`` sends one telemetry and waits for its reply (pipeline depth
    1, what a latency benchmark wants). The real simulator sends two telemetries at open and then one
    per reply, i.e. it keeps TWO frames in flight: ``open_burst`` reproduces that, after which every
    reply answers the frame before last and a round trip includes waiting behind the other frame.
    """

    def __init__(self, url: str = "http://127.0.0.1:4567", timeout: float = 10.0, decimal: str = ".") -> None:
        parts = urlsplit(url if "://" in url else f"http://{url}")
        if parts.scheme not in ("http", "ws"):
            raise BadValue(f"only http:// or ws:// URLs are supported, not {url!r}")
        if decimal not in (".", ","):
            raise BadValue(f"decimal must be '.' or ',', not {decimal!r}")
        self.host = parts.hostname or "127.0.0.1"
        self.port = parts.port or 4567
        self.timeout = timeout
        self.decimal = decimal
        self.ping_interval_s = CLIENT_PING_INTERVAL_S
        self.sid: str | None = None
        self.server_ping_interval_s: float | None = None
        self.pings_answered = 0
        self.pings_sent = 0
        self._ws = WebSocketConnection(self.host, self.port, timeout)
        self._last_ping_sent = 0.0

    # -- context manager -------------------------------------------------------------------------
    def __enter__(self) -> UnityWireClient:
        self.connect()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- connection ------------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the WebSocket and read the Engine.IO open packet; sends nothing else (no ``40``)."""
        self._ws = WebSocketConnection(self.host, self.port, self.timeout)
        self._ws.open("/socket.io/?EIO=4&transport=websocket", user_agent="websocket-sharp/1.0")
        opcode, data = self._read_message()
        text = data.decode("utf-8", errors="replace")
        if opcode != OP_TEXT or not text.startswith("0"):
            self.close()
            raise ConnectionError(f"expected the Engine.IO open packet, got {text[:60]!r}")
        info = json.loads(text[1:])
        self.sid = info.get("sid")
        self.server_ping_interval_s = info.get("pingInterval", 25000) / 1000.0
        self._last_ping_sent = time.monotonic()

    @property
    def socket(self) -> socket.socket:
        """The TCP socket under the WebSocket (hostile tests write raw, unframed bytes to it); connected only."""
        sock = self._ws.socket
        assert sock is not None, "not connected"
        return sock

    def close(self) -> None:
        """Send a WebSocket close frame and close the socket (idempotent)."""
        self._ws.close()

    # -- sending ---------------------------------------------------------------------------------
    def send_text(self, text: str) -> None:
        """Send one raw Engine.IO packet (text frame); no waiting. Public for protocol tests."""
        self._send_frame(OP_TEXT, text.encode("utf-8"))

    def send_bytes(self, data: bytes, opcode: int = OP_TEXT) -> None:
        """Send arbitrary bytes as one frame (for tests of what the server refuses)."""
        self._send_frame(opcode, data)

    def send_telemetry(self, payload: Mapping[str, object] | None) -> None:
        """Emit one ``telemetry`` event as the simulator would; ``None`` is a manual-mode frame.

        Numbers are formatted like Unity (4 decimals) and every value is sent as a string with this
        client's decimal separator; the image (or anything that is not a number) is sent as given.
        """
        self._send_raw(self.telemetry_frame(payload))

    def telemetry_frame(self, payload: Mapping[str, object] | None) -> bytes:
        """The masked WebSocket frame of one ``telemetry`` event (see ``send_telemetry``)."""
        return _frame(OP_TEXT, self.telemetry_text(payload).encode("utf-8"))

    def telemetry_text(self, payload: Mapping[str, object] | None) -> str:
        """The Engine.IO packet text of one ``telemetry`` event (see ``send_telemetry``)."""
        if payload is None:
            return '42["telemetry",null]'
        if not isinstance(payload, dict):  # not something the simulator sends; kept for robustness tests
            return '42["telemetry",' + json.dumps(payload) + "]"
        fields = []
        for key, value in payload.items():
            if isinstance(value, bool) or not isinstance(value, int | float | str):
                fields.append(json.dumps(key) + ":" + json.dumps(value))
                continue
            if isinstance(value, int | float):
                value = f"{value:.4f}"
            if key != "image" and self.decimal != ".":
                value = value.replace(".", self.decimal)
            fields.append(_json_string(key) + ":" + _json_string(value))
        return '42["telemetry",{' + ",".join(fields) + "}]"

    def open_burst(self, payload: Mapping[str, object] | None) -> None:
        """Send two telemetries back to back, as the simulator does when the socket opens.

        After this the loop has pipeline depth 2: read two replies, or keep sending one frame per
        reply (each reply then answers the frame before last).
        """
        self.send_telemetry(payload)
        self.send_telemetry(payload)

    # -- receiving -------------------------------------------------------------------------------
    def receive_reply(self, timeout: float | None = None) -> SteerCommand | None:
        """Wait for the next ``steer`` (returned) or ``manual`` (``None``); pings are handled on the way.

        ``timeout`` bounds the whole wait (``None``: the client's timeout for each read). Raises
        ``TimeoutError`` when nothing arrives in time and ``ConnectionClosed`` when the server closes
        the connection.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            text = self._receive_packet(deadline)
            if text.startswith("42"):
                event, *args = json.loads(text[2:])
                if event == "steer":
                    return parse_steer(args[0] if args else None)
                if event == "manual":
                    return None
                log.debug("ignoring event %r", event)
            elif text.startswith("41") or text.startswith("1"):
                raise ConnectionClosed(f"server closed the session ({text[:20]!r})")
            else:
                log.debug("ignoring packet %r", text[:60])

    def exchange(self, payload: Mapping[str, object] | None) -> tuple[SteerCommand | None, float]:
        """Send one telemetry, wait for its reply; returns (command or None for manual, round trip s).

        The round trip runs from the moment the encoded frame is handed to the socket to the parsed
        reply: what the simulator waits for, excluding building its own message.
        """
        frame = self.telemetry_frame(payload)
        t0 = time.perf_counter()
        self._send_raw(frame)
        reply = self.receive_reply()
        return reply, time.perf_counter() - t0

    # -- internals -------------------------------------------------------------------------------
    def _maybe_ping(self) -> None:
        now = time.monotonic()
        if now - self._last_ping_sent >= self.ping_interval_s:
            self._last_ping_sent = now
            self.pings_sent += 1
            self._ws.send_raw(_frame(OP_TEXT, b"2"))

    def _receive_packet(self, deadline: float | None) -> str:
        """Next Engine.IO packet that is not a ping (server pings are answered with ``3``)."""
        while True:
            opcode, data = self._read_message(deadline)
            if opcode == OP_BINARY:
                log.debug("ignoring a binary frame of %d bytes", len(data))
                continue
            text = data.decode("utf-8")
            if text == "2":
                self.pings_answered += 1
                self.send_text("3")
                continue
            if text.startswith("3"):
                continue
            return text

    def _send_frame(self, opcode: int, payload: bytes) -> None:
        self._send_raw(_frame(opcode, payload))

    def _send_raw(self, frame: bytes) -> None:
        if not self._ws.connected:
            raise ConnectionClosed("not connected")
        if frame[0] & 0x0F == OP_TEXT:
            self._maybe_ping()
        self._ws.send_raw(frame)

    def _read_message(self, deadline: float | None = None) -> tuple[int, bytes]:
        return self._ws.read_message(deadline)
