"""What the monitor adds to drive_server's time per frame: the server's pipeline (decode, preprocess, steering,
monitor, control law) on the same recorded frames with the monitor off and on, interleaved frame by frame in one
run so both see the same machine load."""

from __future__ import annotations

from pathlib import Path
from time import perf_counter
from typing import Any

import numpy as np

from protocol.errors import BadValue


def monitor_cost(model: Path, log_folder: Path, frames: int = 2000, seed: int = 0) -> dict[str, Any]:
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
    from drive_server.serving.model import SteeringModel
    from drive_server.serving.pipeline import DriveConfig, DrivePipeline
    from protocol import parse_telemetry
    from tools.wire.frames import log_frames

    steering = SteeringModel(model)
    steering.warm_up()
    off = DrivePipeline(steering, DriveConfig(monitor=MonitorPolicy(mode=MonitorMode.OFF)))
    on = DrivePipeline(steering, DriveConfig(monitor=MonitorPolicy(mode=MonitorMode.ACT)))
    monitor = on.client_monitor("bench")
    if monitor is None:
        raise BadValue(f"{model.name} carries no monitor")
    source = [parse_telemetry(f.payload()) for f in log_frames(log_folder)]
    order = np.random.default_rng(seed).integers(0, len(source), frames)
    times: dict[str, list[float]] = {"off": [], "on": []}
    for i in order:
        for name, pipeline, mon in (("off", off, None), ("on", on, monitor)):
            t0 = perf_counter()
            pipeline.run(source[i], None, mon)
            times[name].append(perf_counter() - t0)
    out: dict[str, Any] = {"frames": frames, "log": log_folder.name}
    for name, values in times.items():
        ms = np.array(values) * 1000
        out[name] = {"p50_ms": float(np.percentile(ms, 50)), "p99_ms": float(np.percentile(ms, 99))}
    added = (np.array(times["on"]) - np.array(times["off"])) * 1000
    out["added"] = {"p50_ms": float(np.percentile(added, 50)), "p99_ms": float(np.percentile(added, 99))}
    return out
