"""The result record of a closed loop on a recording: small, flat, and enough to compare runs."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np

from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera
from tools.drivelog.loop import LoopResult
from tools.drivelog.road import RoadEdges


def result_record(result: LoopResult, data: Path, frames: int, driver: str, bias: float,
                  camera: UnityCamera = DEFAULT_CAMERA, road: RoadEdges | None = None) -> dict[str, object]:
    """``eta`` (percent), ``interventions``, ``offset_rms_m`` and ``frames``, with what they were measured under."""
    return {
        "data": str(data),
        "driver": driver,
        "steer_bias": bias,
        "eta": round(result.eta, 2),
        "interventions": result.interventions,
        # eta clamps at 0 once take-overs cost more than the drive lasted; this still tells two drivers apart
        "seconds_per_takeover": round(result.driving_time_s / max(1, result.interventions), 2),
        "offset_rms_m": round(result.offset_rms_m, 4),
        "offset_max_m": round(float(np.max(np.abs(result.offsets))) if len(result.offsets) else 0.0, 4),
        "heading_rms_deg": round(float(np.sqrt(np.mean(result.headings ** 2))) if len(result.headings) else 0.0, 3),
        "frames": frames,
        "steps": result.frames,
        "driving_time_s": round(result.driving_time_s, 2),
        "off_road_s": round(result.off_road_s, 2),  # the recorded driver off the road: not counted
        "reversing_s": round(result.reversing_s, 2),  # the recorded driver reversing (person_reverses): not counted
        "takeovers": [{"frame": t.frame, "time_s": round(t.time_s, 2), "offset_m": round(t.offset_m, 3)}
                      for t in result.takeovers],
        "rules": asdict(result.rules),
        "road": None if road is None else {"width_m": round(road.width_m, 3),
                                           "measured_share": round(road.measured_share, 4), "track": road.track},
        "camera": asdict(camera),
    }
