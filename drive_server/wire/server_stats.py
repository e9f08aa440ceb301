"""What a drive server reports of its clients: the latency statistics of every client (connected and gone), the
faults it refused or closed, the line it logs every ``--log-every`` seconds and on stopping, and the files of
``--stats-dump`` (a worker's hand-back to its parent) and ``--stats-json``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from drive_server.observing.stats import FaultCounters, LatencyStats, save_stats, summarize, summary_line
from drive_server.wire.clients import ClientHistory
from drive_server.wire.server_config import ServerConfig, StatsDocument, stats_document
from protocol.runrecords import write_json

if TYPE_CHECKING:
    from collections.abc import Mapping

    from drive_server.serving.pipeline import DrivePipeline
    from drive_server.wire.clients import ClientState
    from drive_server.wire.transport import TransportTuning


class ServerStats:
    """The statistics of ``clients`` (the server's dict of connected clients, read as it changes) and of the
    clients that left, and the fault counters the server's fault log counts into."""

    def __init__(self, config: ServerConfig, pipeline: DrivePipeline, transport: TransportTuning,
                 clients: Mapping[str, ClientState]) -> None:
        self.config, self.pipeline, self.transport, self.clients = config, pipeline, transport, clients
        self.faults = FaultCounters()
        self.history = ClientHistory()
        self._logged_upto: dict[str, int] = {}
        self._logged_frames = -1

    def client_left(self, stats: LatencyStats) -> None:
        """Keep the statistics of a client that disconnected."""
        for name in self.history.add(stats):
            self._logged_upto.pop(name, None)

    def all_stats(self) -> list[LatencyStats]:
        return [*self.history.all_stats(), *(c.stats for c in self.clients.values())]

    def document(self) -> StatsDocument:
        """What ``--stats-json`` holds."""
        return stats_document(self.pipeline.model, self.transport, self.all_stats(), faults=self.faults.as_dict(),
                              limits=self.config.limits)

    def write(self) -> None:
        if self.config.stats_dump is not None:
            save_stats(self.config.stats_dump, self.all_stats())
            write_json(self.config.stats_dump.with_suffix(".faults.json"), self.faults.as_dict(), sort_keys=True)
        if self.config.stats_json is not None:
            write_json(self.config.stats_json, self.document(), sort_keys=True)

    def progress_line(self) -> str | None:
        """Counters since start, percentiles of the frames since the last line; None if no frame came since."""
        stats = self.all_stats()
        frames = sum(s.frames + s.malformed + s.manual for s in stats)
        if frames == self._logged_frames:
            return None
        self._logged_frames = frames
        line = summary_line(summarize(stats, since=self._logged_upto))
        self._logged_upto = {s.name: s.recorded for s in stats}
        return f"{len(self.clients)} client(s): {line}"

    def final_line(self) -> str:
        """Every client's totals and the faults, for the line logged on stopping."""
        faults = ", ".join(f"{kind} {n}" for kind, n in self.faults.as_dict().items())
        return summary_line(summarize(self.all_stats())) + (f" | refused/closed: {faults}" if faults else "")
