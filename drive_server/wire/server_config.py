"""The drive server's settings and the document ``--stats-json`` holds; eventlet-free, so the command line
reads its defaults and the parent of worker processes writes the document without importing the server."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TypedDict

from drive_server.observing.stats import LatencyStats, StatsSummary, summarize
from drive_server.serving.guard import FallbackPolicy
from drive_server.serving.model import SteeringModel
from drive_server.wire.limits import WireLimits
from drive_server.wire.transport import TransportTuning

RETIRED = "retired"


class ClientSummary(StatsSummary):
    """One client's entry of ``--stats-json``: its name, then its totals and percentiles."""

    client: str


class StatsDocument(TypedDict, total=False):
    """What ``--stats-json`` holds (every key; a copy in a benchmark's record may leave ``clients`` out)."""

    model: str
    contract_source: str
    contract: dict[str, object]
    threads: int
    provider: str
    workers: int
    transport: dict[str, object]
    total: StatsSummary
    faults: dict[str, int]
    limits: dict[str, object]
    clients: list[ClientSummary]


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
                   limits: WireLimits | None = None) -> StatsDocument:
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
        "clients": [{"client": s.name, **s.summary()} for s in stats if s.name != RETIRED],
    }
