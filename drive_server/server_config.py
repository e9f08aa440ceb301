"""The drive server's settings and the document ``--stats-json`` holds; eventlet-free, so the command line
reads its defaults and the parent of worker processes writes the document without importing the server."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drive_server.guard import FallbackPolicy
from drive_server.limits import WireLimits
from drive_server.model import SteeringModel
from drive_server.stats import LatencyStats, summarize
from drive_server.transport import TransportTuning

#: Largest accepted Socket.IO message (WireLimits' default). A 320x160 JPEG is ~16 KB (21 KB in base64) at
#: the simulator's quality 75; even pure noise at quality 100 is 102 KB (136 KB in base64). 256 KiB leaves
#: margin for any real frame and refuses anything else before it is buffered.
MAX_MESSAGE_BYTES = WireLimits.max_message_bytes
RETIRED = "retired"


@dataclass(frozen=True)
class ServerConfig:
    """Socket and bookkeeping settings (the control law lives in ``DriveConfig``)."""

    host: str = "127.0.0.1"
    port: int = 4567
    log_every_s: float = 10.0  # period of the one-line latency summary; 0 disables it
    stats_json: Path | None = None
    fallback: FallbackPolicy = field(default_factory=FallbackPolicy)
    transport: TransportTuning = field(default_factory=TransportTuning)
    max_message_bytes: int = MAX_MESSAGE_BYTES
    ping_interval_s: float = 25.0  # Engine.IO heartbeat (the simulator pings every 25 s as well)
    transports: tuple[str, ...] = ("polling", "websocket")  # worker processes accept websocket only
    stats_dump: Path | None = None  # raw statistics for the parent of a worker process
    max_connections: int = WireLimits.max_connections  # open TCP connections (a simulator holds one)
    header_timeout_s: float = WireLimits.header_timeout_s  # to send the request line and headers (and a poll body)
    max_pending_replies: int = WireLimits.max_pending_replies  # queued replies of a client that does not read
    idle_evict_s: float = WireLimits.idle_evict_s  # silence after which, at the cap, a WebSocket gives way
    dashboard: bool = False  # the read-only live view at http://HOST:PORT/ (drive_server.dashboard)

    @property
    def limits(self) -> WireLimits:
        return WireLimits(max_message_bytes=self.max_message_bytes, max_connections=self.max_connections,
                          header_timeout_s=self.header_timeout_s, max_pending_replies=self.max_pending_replies,
                          idle_evict_s=self.idle_evict_s)


def stats_document(model: SteeringModel, transport: TransportTuning, stats: list[LatencyStats],
                   workers: int = 1, faults: dict[str, int] | None = None,
                   limits: WireLimits | None = None) -> dict[str, Any]:
    """What ``--stats-json`` holds: the model, the settings, totals and one entry per client."""
    return {
        "model": str(model.path),
        "contract_source": model.contract_source,
        "contract": model.contract.__dict__,
        "threads": model.config.threads,
        "provider": model.config.provider,
        "workers": workers,
        "transport": transport.__dict__,
        "total": summarize(stats),
        "faults": faults or {},
        "limits": (limits or WireLimits()).__dict__,
        "clients": [dict(client=s.name, **s.summary()) for s in stats if s.name != RETIRED],
    }
