"""A client that behaves exactly like the Unity driving simulator on the wire.

Why a raw-socket client instead of a Socket.IO library: the simulator's own client is unusual
(websocket only, ``User-Agent: websocket-sharp/1.0``, no Origin, never sends the Socket.IO CONNECT
packet ``40``, pings the server itself). Only a client that does exactly that can prove the drive
server copes with it. It is also small and fast (RFC 6455 framing with numpy masking), so it can
drive latency benchmarks without becoming the bottleneck.

Needs only numpy and ``protocol``.
"""

from __future__ import annotations

import base64
import hashlib
import json
import logging
import os
import socket
import struct
import time
from types import TracebackType
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from protocol import ProtocolError, SteerCommand, parse_steer

log = logging.getLogger(__name__)

_WS_GUID = b"258EAFA5-E914-47DA-95CA-C5AB0DC85B11"
_OP_CONT, _OP_TEXT, _OP_BINARY, _OP_CLOSE, _OP_PING, _OP_PONG = 0x0, 0x1, 0x2, 0x8, 0x9, 0xA
#: The Unity client sends its own Engine.IO ping every 25 s (besides answering the server's).
CLIENT_PING_INTERVAL_S = 25.0
_JSON_UNSAFE = ('"', "\\")


class ConnectionClosed(ConnectionError):
    """The server closed the WebSocket (or the Engine.IO session)."""


def mask_payload(payload: bytes, mask: bytes) -> bytes:
    """XOR ``payload`` with the 4-byte WebSocket ``mask`` (RFC 6455 section 5.3), vectorised.

    Viewing the payload as native uint32 words and the mask as the same native word keeps the byte
    order consistent on any endianness; the 0-3 trailing bytes are done separately.
    """
    n = len(payload)
    n4 = n & ~3
    out = bytearray(n)
    if n4:
        words = np.frombuffer(payload, dtype=np.uint32, count=n4 // 4)
        np.bitwise_xor(words, np.frombuffer(mask, dtype=np.uint32)[0], out=np.frombuffer(out, np.uint32, n4 // 4))
    for i in range(n4, n):
        out[i] = payload[i] ^ mask[i & 3]
    return bytes(out)


def _frame(opcode: int, payload: bytes) -> bytes:
    """One final, masked client frame."""
    n = len(payload)
    if n < 126:
        header = struct.pack("!BB", 0x80 | opcode, 0x80 | n)
    elif n < 65536:
        header = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, n)
    else:
        header = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, n)
    mask = os.urandom(4)
    return header + mask + mask_payload(payload, mask)


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
            raise ValueError(f"only http:// or ws:// URLs are supported, not {url!r}")
        if decimal not in (".", ","):
            raise ValueError(f"decimal must be '.' or ',', not {decimal!r}")
        self.host = parts.hostname or "127.0.0.1"
        self.port = parts.port or 4567
        self.timeout = timeout
        self.decimal = decimal
        self.ping_interval_s = CLIENT_PING_INTERVAL_S
        self.sid: str | None = None
        self.server_ping_interval_s: float | None = None
        self.pings_answered = 0
        self.pings_sent = 0
        self._sock: socket.socket | None = None
        self._sock_timeout = timeout
        self._buf = bytearray()
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
        sock = socket.create_connection((self.host, self.port), timeout=self.timeout)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        self._sock_timeout = self.timeout
        key = base64.b64encode(os.urandom(16)).decode("ascii")
        request = (
            "GET /socket.io/?EIO=4&transport=websocket HTTP/1.1\r\n"
            f"Host: {self.host}:{self.port}\r\n"
            "User-Agent: websocket-sharp/1.0\r\n"
            "Upgrade: websocket\r\n"
            "Connection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n"
        )
        sock.sendall(request.encode("ascii"))
        while b"\r\n\r\n" not in self._buf:
            self._fill()
        head, _, rest = bytes(self._buf).partition(b"\r\n\r\n")
        self._buf = bytearray(rest)
        lines = head.decode("latin-1").split("\r\n")
        if not lines[0].startswith("HTTP/1.1 101"):
            self.close()
            raise ConnectionError(f"WebSocket upgrade refused: {lines[0]!r}")
        headers = {k.strip().lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:])}
        accept = base64.b64encode(hashlib.sha1(key.encode("ascii") + _WS_GUID).digest()).decode("ascii")
        if headers.get("sec-websocket-accept") != accept:
            self.close()
            raise ConnectionError("WebSocket upgrade: bad Sec-WebSocket-Accept")
        opcode, data = self._read_message()
        text = data.decode("utf-8", errors="replace")
        if opcode != _OP_TEXT or not text.startswith("0"):
            self.close()
            raise ConnectionError(f"expected the Engine.IO open packet, got {text[:60]!r}")
        info = json.loads(text[1:])
        self.sid = info.get("sid")
        self.server_ping_interval_s = info.get("pingInterval", 25000) / 1000.0
        self._last_ping_sent = time.monotonic()

    def close(self) -> None:
        """Send a WebSocket close frame and close the socket (idempotent)."""
        sock, self._sock = self._sock, None
        if sock is None:
            return
        try:
            sock.sendall(_frame(_OP_CLOSE, struct.pack("!H", 1000)))
        except OSError:
            pass
        finally:
            sock.close()

    # -- sending ---------------------------------------------------------------------------------
    def send_text(self, text: str) -> None:
        """Send one raw Engine.IO packet (text frame); no waiting. Public for protocol tests."""
        self._send_frame(_OP_TEXT, text.encode("utf-8"))

    def send_bytes(self, data: bytes, opcode: int = _OP_TEXT) -> None:
        """Send arbitrary bytes as one frame (for tests of what the server refuses)."""
        self._send_frame(opcode, data)

    def send_telemetry(self, payload: dict[str, Any] | None) -> None:
        """Emit one ``telemetry`` event as the simulator would; ``None`` is a manual-mode frame.

        Numbers are formatted like Unity (4 decimals) and every value is sent as a string with this
        client's decimal separator; the image (or anything that is not a number) is sent as given.
        """
        self._send_raw(self.telemetry_frame(payload))

    def telemetry_frame(self, payload: dict[str, Any] | None) -> bytes:
        """The masked WebSocket frame of one ``telemetry`` event (see ``send_telemetry``)."""
        return _frame(_OP_TEXT, self.telemetry_text(payload).encode("utf-8"))

    def telemetry_text(self, payload: dict[str, Any] | None) -> str:
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

    def open_burst(self, payload: dict[str, Any] | None) -> None:
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

    def exchange(self, payload: dict[str, Any] | None) -> tuple[SteerCommand | None, float]:
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
            self._sock.sendall(_frame(_OP_TEXT, b"2"))  # type: ignore[union-attr]

    def _receive_packet(self, deadline: float | None) -> str:
        """Next Engine.IO packet that is not a ping (server pings are answered with ``3``)."""
        while True:
            opcode, data = self._read_message(deadline)
            if opcode == _OP_BINARY:
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
        if self._sock is None:
            raise ConnectionClosed("not connected")
        if frame[0] & 0x0F == _OP_TEXT:
            self._maybe_ping()
        try:
            self._sock.sendall(frame)
        except OSError as exc:
            raise ConnectionClosed(f"connection lost: {exc}") from None

    def _fill(self, deadline: float | None = None) -> None:
        if self._sock is None:
            raise ConnectionClosed("not connected")
        timeout = self.timeout if deadline is None else min(self.timeout, deadline - time.monotonic())
        if timeout <= 0:
            raise TimeoutError("no reply from the server in time")
        if timeout != self._sock_timeout:  # settimeout costs two fcntl calls: only when it changes
            self._sock.settimeout(timeout)
            self._sock_timeout = timeout
        try:
            chunk = self._sock.recv(65536)
        except TimeoutError:
            raise TimeoutError("no reply from the server in time") from None
        except OSError as exc:
            raise ConnectionClosed(f"connection lost: {exc}") from None
        if not chunk:
            raise ConnectionClosed("server closed the connection")
        self._buf += chunk

    def _need(self, n: int, deadline: float | None) -> None:
        while len(self._buf) < n:
            self._fill(deadline)

    def _read_message(self, deadline: float | None = None) -> tuple[int, bytes]:
        """One complete data message (fragments joined); control frames are handled here."""
        parts: list[bytes] = []
        first_opcode = None
        while True:
            self._need(2, deadline)
            b0, b1 = self._buf[0], self._buf[1]
            fin, opcode, n, pos = b0 & 0x80, b0 & 0x0F, b1 & 0x7F, 2
            if n == 126:
                self._need(4, deadline)
                n, pos = struct.unpack_from("!H", self._buf, 2)[0], 4
            elif n == 127:
                self._need(10, deadline)
                n, pos = struct.unpack_from("!Q", self._buf, 2)[0], 10
            mask = None
            if b1 & 0x80:  # servers must not mask, but tolerate it
                self._need(pos + 4, deadline)
                mask, pos = bytes(self._buf[pos:pos + 4]), pos + 4
            self._need(pos + n, deadline)
            data = bytes(self._buf[pos:pos + n])
            del self._buf[:pos + n]
            if mask is not None:
                data = mask_payload(data, mask)
            if opcode == _OP_CLOSE:
                self.close()
                raise ConnectionClosed("server sent a WebSocket close frame"
                                       + (f" (code {struct.unpack('!H', data[:2])[0]})" if len(data) >= 2 else ""))
            if opcode == _OP_PING:
                self._send_frame(_OP_PONG, data)
                continue
            if opcode == _OP_PONG:
                continue
            if opcode != _OP_CONT:
                first_opcode = opcode
            parts.append(data)
            if fin:
                if first_opcode is None:
                    raise ProtocolError("WebSocket continuation frame without a first frame")
                return first_opcode, parts[0] if len(parts) == 1 else b"".join(parts)
