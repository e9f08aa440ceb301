"""A video of a recording (``rbc video DIR``): a Unity training log, an ``rbc collect`` dataset, or what
``drive_server --record`` saved of an autonomous run, with steering, pedals and speed overlaid.

A drive_server recording has no frames while a person holds a key (the simulator then sends nothing to
answer with a picture), so a pause in the frame times longer than ``gap_s`` is where someone took over:
the first frame after it is marked as an intervention, as ``rbc sim --video`` marks take-overs.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from protocol.datalog import read_log
from protocol.datalog_writer import parse_frame_stamp
from protocol.errors import BadValue
from protocol.facts import MAX_STEERING_DEG
from tools.sim.pictures.text import draw_text
from tools.sim.pictures.video import VideoWriter

log = logging.getLogger(__name__)

#: A pause in the frame times longer than this is drawn as an intervention (someone took over).
GAP_S = 1.0
#: How long (video seconds) an intervention stays marked.
MARK_S = 1.5


@dataclass
class VideoSummary:
    path: Path
    frames: int
    fps: float
    interventions: int
    backend: str


def frame_times(names: list[str]) -> np.ndarray | None:
    """Seconds since the first frame, from the recorder's file names; None if the names carry no time."""
    stamps = [parse_frame_stamp(n) for n in names]
    if any(s is None for s in stamps) or not stamps:
        return None
    return np.array([(s - stamps[0]).total_seconds() for s in stamps])  # type: ignore[operator]


def overlay(bgr: np.ndarray, t: float, steering: float, throttle: float, brake: float, speed: float,
            unit: str, gap: float | None) -> np.ndarray:
    """The frame at 2x with time, steering, pedals and speed; a red border after an intervention."""
    img = cv2.resize(bgr, (bgr.shape[1] * 2, bgr.shape[0] * 2), interpolation=cv2.INTER_LINEAR)
    h, w = img.shape[:2]
    draw_text(img, f"t {t:6.1f} s", (8, 22), 17, box=True)
    draw_text(img, f"steer {steering * MAX_STEERING_DEG:+5.1f} deg ({steering:+.2f})", (8, 46), 17, box=True)
    pedal = f"brake {brake:.2f}" if brake > 0 else f"throttle {throttle:.2f}"
    draw_text(img, f"{pedal}  speed {speed:4.1f} {unit}", (8, 70), 17, box=True)
    cx, y0 = w // 2, h - 18
    cv2.rectangle(img, (cx - 150, y0), (cx + 150, y0 + 10), (0, 0, 0), -1)
    end = cx + int(round(150 * max(-1.0, min(1.0, steering))))  # + = right, as in the simulator
    cv2.rectangle(img, (min(cx, end), y0 + 2), (max(cx, end), y0 + 8), (0, 220, 255), -1)
    cv2.line(img, (cx, y0 - 3), (cx, y0 + 13), (255, 255, 255), 1)
    if gap is not None:
        cv2.rectangle(img, (0, 0), (w - 1, h - 1), (60, 60, 230), 6)
        draw_text(img, f"INTERVENTION: {gap:.1f} s without frames (a person took over)", (8, 94), 15,
                  (80, 80, 255), box=True)
    return img


def write_recording_video(source: Path, out: Path, fps: float | None = None, speed_unit: str = "mph",
                          gap_s: float = GAP_S, progress=None) -> VideoSummary:
    """Every centre frame of the log at ``source``, annotated, into ``out`` (H.264 where PyAV is installed)."""
    samples, _ = read_log(source)
    times = frame_times([s.center.name for s in samples])
    if fps is None:
        steps = np.diff(times) if times is not None and len(times) > 1 else np.array([])
        steps = steps[(steps > 0) & (steps < gap_s)]
        fps = float(np.clip(1.0 / np.median(steps), 1.0, 60.0)) if len(steps) else 15.0
    if times is None:
        times = np.arange(len(samples)) / fps
    gaps = np.concatenate([[0.0], np.diff(times)])
    writer = VideoWriter(out, fps)
    marked_until, last_gap, interventions = -1.0, 0.0, 0
    try:
        for i, s in enumerate(samples):
            bgr = cv2.imread(str(s.center), cv2.IMREAD_COLOR)
            if bgr is None:
                log.warning("%s: unreadable frame, skipped", s.center)
                continue
            if gaps[i] > gap_s:
                interventions += 1
                last_gap, marked_until = float(gaps[i]), writer.frames + MARK_S * fps
            gap = last_gap if writer.frames < marked_until else None
            writer.write(overlay(bgr, float(times[i]), s.steering, s.throttle, s.brake, s.speed,
                                 "km/h" if speed_unit == "kmh" else "mph", gap))
            if progress is not None:
                progress(i + 1, len(samples))
    finally:
        path = writer.close()
    if path is None:
        raise BadValue(f"{source}: no readable frame to make a video of")
    return VideoSummary(path, writer.frames, fps, interventions, writer.backend)
