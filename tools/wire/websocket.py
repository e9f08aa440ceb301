"""A small RFC 6455 client connection: the upgrade handshake, masked frames out, messages in.

Why not a WebSocket library: the Unity simulator's client (websocket-sharp) sends exactly this
handshake (``User-Agent: websocket-sharp/1.0``, no Origin), and only a client that does exactly
that proves the server copes with it; it is also fast enough (numpy masking) to drive latency
benchmarks without becoming the bottleneck. Needs only numpy and ``protocol``.
"""

from __future__ import annotations

import base64
import hashlib
import os
import socket
import struct
import time

from protocol import ProtocolError
from protocol.errors import UserError
from protocol.websocket import xor_mask

WS_GUID = b"258EAFA5-E914-47DA-95CA-C5AB0DC85B11"
OP_CONT, OP_TEXT, OP_BINARY, OP_CLOSE, OP_PING, OP_PONG = 0x0, 0x1, 0x2, 0x8, 0x9, 0xA


class ConnectionClosed(UserError, ConnectionError):
    """The server closed the WebSocket (or the Engine.IO session)."""

    hint = "is drive_server running at that address?"


def client_frame(opcode: int, payload: bytes, fin: bool = True) -> bytes:
    """One masked client frame; ``fin=False`` (and opcode 0 for the next ones) splits a message in fragments."""
    n = len(payload)
    b0 = (0x80 if fin else 0) | opcode
    if n < 126:
        header = struct.pack("!BB", b0, 0x80 | n)
    elif n < 65536:
        header = struct.pack("!BBH", b0, 0x80 | 126, n)
    else:
        header = struct.pack("!BBQ", b0, 0x80 | 127, n)
    mask = os.urandom(4)
    return header + mask + xor_mask(payload, mask)


class WebSocketConnection:
    """One client WebSocket over a blocking TCP socket with a per-read timeout."""

    def __init__(self, host: str, port: int, timeout: float) -> None:
        self.host, self.port, self.timeout = host, port, timeout
        self._sock: socket.socket | None = None
        self._sock_timeout = timeout
        self._buf = bytearray()

    @property
    def connected(self) -> bool:
        return self._sock is not None

    @property
    def socket(self) -> socket.socket | None:
        """The TCP socket (for tests and benchmarks that write raw bytes or shrink its buffers)."""
        return self._sock

    def open(self, path: str, user_agent: str) -> None:
        """Connect and upgrade ``path``; raises ``ConnectionError`` if the server refuses."""
        sock = socket.create_connection((self.host, self.port), timeout=self.timeout)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock, self._sock_timeout = sock, self.timeout
        key = base64.b64encode(os.urandom(16)).decode("ascii")
        request = (
            f"GET {path} HTTP/1.1\r\n"
            f"Host: {self.host}:{self.port}\r\n"
            f"User-Agent: {user_agent}\r\n"
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
        accept = base64.b64encode(hashlib.sha1(key.encode("ascii") + WS_GUID).digest()).decode("ascii")
        if headers.get("sec-websocket-accept") != accept:
            self.close()
            raise ConnectionError("WebSocket upgrade: bad Sec-WebSocket-Accept")

    def close(self) -> None:
        """Send a close frame (code 1000) and close the socket (idempotent)."""
        sock, self._sock = self._sock, None
        if sock is None:
            return
        try:
            sock.sendall(client_frame(OP_CLOSE, struct.pack("!H", 1000)))
        except OSError:
            pass
        finally:
            sock.close()

    def send_raw(self, frame: bytes) -> None:
        """Send an encoded frame (see :func:`client_frame`)."""
        if self._sock is None:
            raise ConnectionClosed("not connected")
        try:
            self._sock.sendall(frame)
        except OSError as exc:
            raise ConnectionClosed(f"connection lost: {exc}") from None

    def read_message(self, deadline: float | None = None) -> tuple[int, bytes]:
        """One complete data message (fragments joined); pings are answered, a close frame raises."""
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
                data = xor_mask(data, mask)
            if opcode == OP_CLOSE:
                self.close()
                raise ConnectionClosed("server sent a WebSocket close frame"
                                       + (f" (code {struct.unpack('!H', data[:2])[0]})" if len(data) >= 2 else ""))
            if opcode == OP_PING:
                self.send_raw(client_frame(OP_PONG, data))
                continue
            if opcode == OP_PONG:
                continue
            if opcode != OP_CONT:
                first_opcode = opcode
            parts.append(data)
            if fin:
                if first_opcode is None:
                    raise ProtocolError("WebSocket continuation frame without a first frame")
                return first_opcode, parts[0] if len(parts) == 1 else b"".join(parts)

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
