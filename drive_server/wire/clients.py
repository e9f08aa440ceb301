"""What the drive server remembers of its clients: each connected simulator's state, and the statistics
of the ones that left (bounded, however many connect and disconnect)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drive_server.observing.stats import LatencyStats
from drive_server.serving.guard import FrameGuard
from drive_server.wire.connections import unsent_bytes
from drive_server.wire.limits import MAX_UNSENT_BYTES
from drive_server.wire.server_config import RETIRED

if TYPE_CHECKING:
    from drive_server.observing.dashboard import LiveFrame
    from drive_server.serving.client_monitor import ClientMonitor
    from drive_server.serving.smoothing import SteeringSmoother
    from drive_server.wire.patches import TcpSocket
    from drive_server.wire.patches.eventlet_engineio import EngineSession

#: Disconnected clients whose statistics are kept individually (older ones only add to the counters).
MAX_FINISHED_CLIENTS = 64


@dataclass
class ClientState:
    """What the server remembers about one connected simulator."""

    sid: str
    eio_sid: str | None
    direct: bool  # replies handed to engine.io directly (``TransportTuning.direct_reply``)
    user_agent: str
    stats: LatencyStats
    guard: FrameGuard
    socket: TcpSocket | None = None  # the WebSocket's TCP socket (None for long-polling)
    replies: int = 0
    unsent: int = 0
    live: LiveFrame | None = None  # the latest answered frame, for the live view
    smoother: SteeringSmoother | None = None  # this client's steering smoothing (None: off)
    monitor: ClientMonitor | None = None  # this client's misbehaviour monitor (None: off)

    def not_reading(self, session: EngineSession, max_pending: int) -> bool:
        """Replies pile up in engine.io's queue, or (checked every 32 replies: one ioctl) in the kernel."""
        if session.queue.qsize() >= max_pending:
            return True
        self.replies += 1
        if self.replies % 32 or self.socket is None:
            return False
        self.unsent = unsent_bytes(self.socket)
        return self.unsent > MAX_UNSENT_BYTES


class ClientHistory:
    """Statistics of disconnected clients: the last ``MAX_FINISHED_CLIENTS`` one by one, older ones summed."""

    def __init__(self) -> None:
        self.finished: deque[LatencyStats] = deque()  # disconnected clients, newest last
        self.retired = LatencyStats(RETIRED, capacity=1)  # counters of clients dropped from ``finished``

    def add(self, stats: LatencyStats) -> list[str]:
        """Keep ``stats`` of a client that left; returns the names of those folded into the totals."""
        self.finished.append(stats)
        folded = []
        while len(self.finished) > MAX_FINISHED_CLIENTS:  # bound memory over many reconnections
            old = self.finished.popleft()
            self.retired.absorb_counters(old)
            folded.append(old.name)
        return folded

    def all_stats(self) -> list[LatencyStats]:
        return [self.retired, *self.finished]
