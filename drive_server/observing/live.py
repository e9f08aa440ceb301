"""What the live view shows of a drive server: its model and control law, and each client's latest frame,
counters and recent latency, built from data the server keeps anyway (nothing is computed per frame)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Protocol

from drive_server.observing.dashboard import RECENT_FRAMES
from drive_server.observing.stats import STAGES, summarize
from protocol.units import to_kmh

if TYPE_CHECKING:
    from drive_server.observing.dashboard import Dashboard, LiveFrame
    from drive_server.observing.stats import LatencyStats
    from drive_server.serving.client_monitor import ClientMonitor
    from drive_server.serving.guard import FrameGuard
    from drive_server.serving.pipeline import DriveConfig, DrivePipeline


class Watched(Protocol):
    """What the live view reads of a connected client (a ``drive_server.wire.clients.ClientState``; named so, not
    imported: the wire sits above the observing room, ``drive_server.ALLOWED_IMPORTS``)."""

    @property
    def sid(self) -> str: ...

    @property
    def user_agent(self) -> str: ...

    @property
    def stats(self) -> LatencyStats: ...

    @property
    def guard(self) -> FrameGuard: ...

    @property
    def live(self) -> LiveFrame | None: ...

    @property
    def monitor(self) -> ClientMonitor | None: ...


class Served(Protocol):
    """What the live view reads of a ``DriveServer`` (named so, not imported: the server imports this module)."""

    @property
    def pipeline(self) -> DrivePipeline: ...

    @property
    def clients(self) -> Mapping[str, Watched]: ...

    @property
    def dashboard(self) -> Dashboard | None: ...


def server_view(server: Served) -> dict[str, object]:
    """The model, its input contract and the control law's parameters."""
    pipeline = server.pipeline
    cfg = pipeline.config
    return {
        "model": pipeline.model.path.name, "contract": pipeline.contract.__dict__,
        "control": {"speed_limit_kmh": cfg.law.speed_limit_kmh, "steer_limit_deg": cfg.law.steer_limit_deg,
                    "tau": cfg.law.tau,
                    "speed_unit": cfg.speed_unit.value, "smoothing": pipeline.smoothing},
        "monitor": _monitor_view(pipeline),
        "clients": len(server.clients), "viewers": server.dashboard.viewers if server.dashboard else 0,
    }


def _monitor_view(pipeline: DrivePipeline) -> dict[str, object] | None:
    spec = pipeline.monitor_spec
    if spec is None:
        return None
    return {"score": spec.score, "warn": spec.warn, "alarm": spec.alarm, "window": spec.window,
            "mode": pipeline.config.monitor.mode.value}


def client_view(client: Watched, cfg: DriveConfig, with_latency: bool, now: float) -> dict[str, object]:
    """One simulator's panel: latest frame (the JPEG as it was sent), counters, recent latency."""
    stats, guard = client.stats, client.guard
    counters: dict[str, int] = {"frames": stats.frames, "malformed": stats.malformed, "manual (null)": stats.manual,
                                "non-finite outputs": getattr(stats, "bad_output", 0), "held": guard.held,
                                "stopped": guard.stopped}
    entry: dict[str, object] = {"sid": client.sid, "agent": client.user_agent, "speed_unit": cfg.speed_unit.value,
                                "counters": counters}
    frame = client.live
    if frame is not None:
        shown: dict[str, object] = {
            "image": frame.image_b64, "age_s": round(now - frame.t, 2), "steering": round(frame.steering, 4),
            "steering_deg": round(cfg.law.steering_deg(frame.steering), 2), "throttle": round(frame.throttle, 4),
            "speed": round(frame.speed, 2), "speed_kmh": round(to_kmh(frame.speed, cfg.speed_unit), 2),
            "fallback": frame.fallback}
        if frame.monitor is not None:
            shown["monitor"] = {"score": round(frame.monitor.score, 5), "mean": round(frame.monitor.mean, 5),
                                "state": frame.monitor.level.label}
        entry["frame"] = shown
    monitor = getattr(client, "monitor", None)
    if monitor is not None:
        counters.update({"monitor warnings": monitor.state.episodes["warning"],
                                  "monitor alarms": monitor.state.episodes["alarm"]})
        if monitor.failed:
            entry["monitor_failed"] = monitor.failed
    if with_latency:
        recent = summarize([stats], since={stats.name: stats.recorded - RECENT_FRAMES})["stages_ms"]
        entry["latency"] = {stage: {"p50": recent[stage]["p50"], "p99": recent[stage]["p99"]}
                            for stage in STAGES if stage in recent}
    return entry


def snapshot(server: Served, with_latency: bool) -> dict[str, object]:
    """One push to every viewer (``with_latency``: percentiles too, a few times a second)."""
    now = time.perf_counter()
    cfg = server.pipeline.config
    return {"server": server_view(server),
            "clients": [client_view(c, cfg, with_latency, now) for c in list(server.clients.values())]}


def make_dashboard(server: Served) -> Dashboard:
    """The live view of ``server`` on eventlet: its ticker and viewer queues are greenthread primitives."""
    import eventlet
    import eventlet.queue

    from drive_server.observing.dashboard import Dashboard

    return Dashboard(lambda with_latency: snapshot(server, with_latency), sleep=eventlet.sleep, spawn=eventlet.spawn,
                     make_queue=lambda size: eventlet.queue.LightQueue(size))
