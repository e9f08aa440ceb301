"""The server's limits, enforced before work is done: no client can stall, starve or exhaust the server.

What the libraries leave open, and what this module closes (each item of issue #10 in brackets):

- Connections [8]: eventlet's WSGI server has no header timeout and queues connection 1,025 forever
  behind 1,024 half-open ones. ``protocol_class`` gives every connection ``header_timeout_s`` to send
  its request line and headers, caps the number of connections, and when the cap is reached closes the
  oldest connection still sending its headers (a half-open flood cannot keep clients out), else the
  upgraded WebSocket silent longest if it has sent nothing for ``idle_evict_s`` (an idle socket would
  otherwise hold its slot until the ping timeout, 45 s: a burst of them filled the cap), or, if there
  is neither, refuses the new one with a 503 and one log line.
- Long-polling bodies [1]: engine.io answers an oversized POST by closing the session with
  ``wait=True``, which waits forever for a poll the client never sends (greenthread and socket kept,
  CLOSE_WAIT). ``polling_gate`` answers 413 from the Content-Length alone, before reading the body,
  and frees the connection; it also bounds the time to send the body and checks its packets.
- WebSocket messages [3]: eventlet checks each frame against ``max_frame_length`` but buffers any
  number of continuation frames. ``limited_message_class`` bounds the whole message while it arrives.
- Packets [5, 6, 7]: engine.io turns an empty or non-numeric text packet into an exception that ends up
  as an HTTP 500 written into the upgraded stream, and json-decodes some packets with unbounded depth
  (RecursionError). ``packet_problem`` refuses, before any library parses it, what no Socket.IO client
  sends; the connection is then closed with a close frame (1002).
- Fairness [4]: with ``async_handlers=False`` a reader whose socket always has data never yields to
  the event loop. The WebSocket reader yields after every message (one message per connection per turn).

Everything here is logged through ``FaultLog``: one line per kind of fault and interval, counted.
eventlet is imported only inside the functions that need it, so the CLI can check options and the
model before paying for (or printing anything from) eventlet.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from time import monotonic

from drive_server.observing.stats import FaultCounters
from protocol.errors import BadValue

log = logging.getLogger(__name__)

#: Deepest JSON nesting accepted in a Socket.IO packet (a telemetry is 2 deep).
MAX_JSON_DEPTH = 32
#: Longest run of number characters outside strings (a telemetry sends numbers as strings).
MAX_NUMBER_CHARS = 64
#: Most JSON structure outside strings (a telemetry has ~40 characters of it; the bound keeps the depth scan short).
MAX_SKELETON_CHARS = 1024
#: Engine.IO packets the client may send besides a message (``4...``): close, ping, pong, upgrade, noop.
_CONTROL_PACKETS = frozenset(["1", "2", "3", "2probe", "3probe", "5", "6"])
_NUMBER_RUN = re.compile(r"[0-9.eE+-]{" + str(MAX_NUMBER_CHARS + 1) + ",}")
_BRACKETS = re.compile(r"[\[\]{}]")
_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"')
#: A Socket.IO EVENT packet (optionally with an ack id) whose event is ``telemetry``.
TELEMETRY_EVENT = re.compile(r'2[0-9]*\["telemetry"')
#: Bytes the kernel may hold unsent for one connection before its client counts as not reading. Replies
#: are ~70 bytes and a simulator has two in flight; the auto-tuned send buffer (MBs) would otherwise let
#: a client that never reads be served ~100,000 frames before the pending-reply queue starts to grow.
MAX_UNSENT_BYTES = 64 * 1024
#: WebSocket close code for a protocol error (RFC 6455 section 7.4.1).
CLOSE_PROTOCOL_ERROR = 1002


@dataclass(frozen=True)
class WireLimits:
    """Limits of one server (``--max-connections``, ``--header-timeout``, ``--idle-evict``, ``--max-pending``,
    message size)."""

    #: Largest accepted Socket.IO message. A 320x160 JPEG is ~16 KB (21 KB in base64) at the simulator's
    #: quality 75; even pure noise at quality 100 is 102 KB (136 KB in base64). 256 KiB leaves margin for any
    #: real frame and refuses anything else before it is buffered.
    max_message_bytes: int = 256 * 1024
    max_connections: int = 256
    header_timeout_s: float = 10.0
    max_pending_replies: int = 64
    #: Seconds an upgraded WebSocket may stay silent before, at the cap, it gives its slot to a new client.
    #: A simulator sends 10-30 telemetries a second and pings every 25 s; 5 s is far from both.
    idle_evict_s: float = 5.0

    def __post_init__(self) -> None:
        if self.max_message_bytes < 1024:
            raise BadValue(f"the message size limit must be >= 1024 bytes, got {self.max_message_bytes}")
        if self.max_connections < 1:
            raise BadValue(f"--max-connections must be >= 1, got {self.max_connections}")
        if not self.header_timeout_s > 0:
            raise BadValue(f"--header-timeout must be > 0 s, got {self.header_timeout_s}")
        if not self.idle_evict_s > 0:
            raise BadValue(f"--idle-evict must be > 0 s, got {self.idle_evict_s}")
        if self.max_pending_replies < 2:  # the simulator keeps two frames in flight
            raise BadValue(f"--max-pending must be >= 2, got {self.max_pending_replies}")


class FaultLog:
    """At most ``burst`` lines per kind of fault per ``interval_s`` (the rest counted, and said on the next line).

    Why: input a client can send must never flood the log (one "46" once meant 4,000 tracebacks).
    Every fault is counted in ``counters`` whether or not its line is written. ``level``, ``burst`` and
    no ``counters`` serve events that are not faults but that a client can repeat at will (connecting, say).
    """

    def __init__(self, counters: FaultCounters | None, interval_s: float = 5.0, level: int = logging.WARNING,
                 burst: int = 1, logger: logging.Logger = log) -> None:
        self.counters = counters
        self.logger = logger
        self.interval_s = interval_s
        self.level = level
        self.burst = burst
        self._last: dict[str, float] = {}  # start of the kind's current interval
        self._used: dict[str, int] = {}  # lines written in it
        self._suppressed: dict[str, int] = {}

    def report(self, kind: str, message: str, *args: object, count: bool = True) -> None:
        """Log ``message % args`` unless ``burst`` lines of this kind were written in the current
        interval; ``count=False`` for faults counted elsewhere (per client)."""
        if count and self.counters is not None:
            self.counters.add(kind)
        now = monotonic()
        if now - self._last.get(kind, -1e18) >= self.interval_s:
            self._last[kind], self._used[kind] = now, 0
        if self._used[kind] >= self.burst:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return
        self._used[kind] += 1
        more = self._suppressed.pop(kind, 0)
        self.logger.log(self.level, message + (f" [{more} more like it not logged]" if more else ""), *args)


# -- packets -------------------------------------------------------------------------------------
def json_problem(text: str) -> str | None:
    """Why the JSON in ``text`` is too deep or has an oversized number, or None. Cheap: strings (the
    base64 image) are cut out first, so only the few characters of structure are looked at."""
    if "\\" in text:
        skeleton = _STRING.sub('""', text)
    else:
        parts = text.split('"')
        if len(parts) % 2 == 0:
            return "unterminated JSON string"
        skeleton = "".join(parts[0::2])
    if len(skeleton) > MAX_SKELETON_CHARS:
        return f"too much JSON structure ({len(skeleton)} characters outside strings)"
    if _NUMBER_RUN.search(skeleton):
        return f"a JSON number longer than {MAX_NUMBER_CHARS} characters"
    depth = deepest = 0
    for match in _BRACKETS.finditer(skeleton):
        depth += 1 if match.group() in "[{" else -1
        deepest = max(deepest, depth)
    if deepest > MAX_JSON_DEPTH:
        return f"JSON nested {deepest} deep (at most {MAX_JSON_DEPTH})"
    return None


def packet_problem(data: str | bytes) -> str | None:
    """Why an Engine.IO packet from a client is refused before any library parses it, or None.

    Accepted: a message ``4`` carrying a Socket.IO packet of type 0-3 (CONNECT, DISCONNECT, EVENT, ACK),
    and the control packets close, ping, pong, upgrade, noop. Everything else is a protocol error:
    binary data (the simulator protocol has none), empty or non-numeric text, Socket.IO binary packets
    (``45``/``46`` once made every later frame on the connection wait for attachments that never came).
    Depth and number size of the JSON are checked separately (``json_problem``), since a bad telemetry
    is still answered.
    """
    if not isinstance(data, str):
        return "binary frame (the simulator protocol has none)"
    if not data:
        return "empty packet"
    if data[0] != "4":
        return None if data in _CONTROL_PACKETS else f"not an Engine.IO packet: {data[:20]!r}"
    kind = data[1:2]
    if kind in ("0", "1", "2", "3"):
        return None
    if kind in ("5", "6"):
        return "Socket.IO binary packet (the simulator protocol has none)"
    return f"not a Socket.IO packet: {data[:20]!r}"


# -- WebSocket -------------------------------------------------------------------------------------
def close_reason(text: str) -> str:
    """``text`` cut to what a close frame can carry (control frames hold at most 125 bytes)."""
    return text.encode("utf-8")[:100].decode("utf-8", errors="ignore")


# -- long-polling ------------------------------------------------------------------------------------


# -- connections ---------------------------------------------------------------------------------------
