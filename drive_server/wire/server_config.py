"""The drive server's settings and the document ``--stats-json`` holds; eventlet-free, so the command line
reads its defaults and the parent of worker processes writes the document without importing the server."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drive_server.observing.stats import LatencyStats, summarize
from drive_server.serving.guard import FallbackPolicy
from drive_server.serving.model import SteeringModel
from drive_server.wire.limits import WireLimits
from drive_server.wire.transport import TransportTuning

RETIRED = "retired"


@dataclass(frozen=True)
class ServerConfig:
    """Socket and bookkeeping settings (the control law lives in ``DriveConfig``, the limits in ``WireLimits``)."""

    host: str = "127.0.0.1"
    port: int = 4567
    log_every_s: float = 10.0  # period of the one-line latency summary; 0 disables it
    stats_json: Path | None = None
    fallback: FallbackPolicy = field(default_factory=FallbackPolicy)
    transport: TransportTuning = field(default_factory=TransportTuning)
    ping_interval_s: float = 25.0  # Engine.IO heartbeat (the simulator pings every 25 s as well)
    transports: tuple[str, ...] = ("polling", "websocket")  # worker processes accept websocket only
    stats_dump: Path | None = None  # raw statistics for the parent of a worker process
    limits: WireLimits = field(default_factory=WireLimits)  # connections, header timeout, replies, message size
    dashboard: bool = False  # the read-only live view at http://HOST:PORT/ (drive_server.observing.dashboard)


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
