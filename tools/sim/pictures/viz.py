"""Pictures of a run: a top-down trajectory map, a strip of camera frames, an H.264 video.

The map shows where the car went, coloured by cross-track error, with every intervention marked
and listed, so a failed run can be understood at a glance; the strip and video show what the
driver saw and did.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from protocol.errors import BadValue
from protocol.facts import MAX_STEERING_DEG
from tools.sim.driving.scenario import FrameEvent, RunResult
from tools.sim.pictures.text import draw_text
from tools.sim.track.road import Track
from tools.sim.vehicle.kinematic import mps_to_kmh

log = logging.getLogger(__name__)

_BG = (34, 40, 36)  # BGR
_GRASS = (52, 70, 54)
_ROAD = (92, 92, 92)
_EDGE = (200, 200, 200)
_TEXT = (235, 235, 235)
_MUTED = (170, 170, 170)
_CAUSE_COLORS = {"off_road": (60, 60, 255), "cone": (0, 140, 255), "stuck": (255, 120, 255),
                 "wrong_way": (255, 200, 0)}


def _colormap(values: np.ndarray, vmax: float) -> np.ndarray:
    """BGR colours (n, 3) of ``values`` in [0, vmax] on OpenCV's TURBO map."""
    idx = np.clip(values / max(vmax, 1e-9) * 255.0, 0, 255).astype(np.uint8)
    return cv2.applyColorMap(idx.reshape(-1, 1), cv2.COLORMAP_TURBO).reshape(-1, 3)


@dataclass(frozen=True)
class _View:
    """World metres -> map pixels (north up)."""

    x0: float
    y1: float
    scale: float  # px per metre
    pad: int

    def px(self, xy: np.ndarray | Sequence[float]) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.stack([(xy[:, 0] - self.x0) * self.scale + self.pad,
                         (self.y1 - xy[:, 1]) * self.scale + self.pad], 1)

    def ipx(self, xy: np.ndarray, shift: int = 4) -> np.ndarray:
        return np.round(self.px(xy) * (1 << shift)).astype(np.int32)


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float = 0.5, color=_TEXT, thick: int = 1,
          box: bool = False) -> None:
    """Anti-aliased text (``scale`` as OpenCV's: 0.5 is about 14 px); ``box`` puts a dark plate behind it."""
    draw_text(img, text, org, px=max(9, round(scale * 28)), color=color, box=box)


def _draw_road(img: np.ndarray, view: _View, track: Track) -> None:
    closed = np.vstack([track.centerline, track.centerline[:1]])
    pts = view.ipx(closed)
    shoulder = max(1, int(round((track.road_width + 2 * track.shoulder_width) * view.scale)))
    road = max(1, int(round(track.road_width * view.scale)))
    cv2.polylines(img, [pts], False, (70, 88, 104), shoulder, cv2.LINE_AA, 4)
    cv2.polylines(img, [pts], False, _EDGE, road + 2, cv2.LINE_AA, 4)
    cv2.polylines(img, [pts], False, _ROAD, max(1, road - 2), cv2.LINE_AA, 4)
    if track.lanes == 2:  # dashed centre line
        step = max(1, int(round(3.0 / track.spacing)))
        for i in range(0, len(closed) - step, 3 * step):
            cv2.polylines(img, [pts[i:i + step + 1]], False, (60, 200, 230), 1, cv2.LINE_AA, 4)


def write_trajectory_map(result: RunResult, path: str | Path, size: int = 1000) -> Path:
    """Top-down map of the run: road, trajectory coloured by |cross-track error|, interventions, legend."""
    from tools.sim.track.files import get_track

    track = get_track(result.config.track)
    trace = result.trace
    margin = track.road_width + 8.0
    lo = track.centerline.min(0) - margin
    hi = track.centerline.max(0) + margin
    scale = size / float(max(hi - lo))
    pad, panel = 10, 330
    w = int(round((hi[0] - lo[0]) * scale)) + 2 * pad
    h = int(round((hi[1] - lo[1]) * scale)) + 2 * pad
    view = _View(float(lo[0]), float(hi[1]), scale, pad)
    img = np.full((max(h, 560), w + panel, 3), _BG, np.uint8)
    img[:h, :w] = _GRASS
    _draw_road(img, view, track)

    vmax = track.road_width / 2
    if trace is not None and len(trace.t) > 1:
        xy = np.stack([trace.x, trace.y], 1)
        p = view.ipx(xy)
        colors = _colormap(np.abs(trace.cte), vmax)
        jump = np.hypot(np.diff(trace.x), np.diff(trace.y)) > 2.0  # resets are not driven
        thick = max(2, int(round(0.5 * scale)))
        stride = max(1, len(p) // 6000)
        for i in range(0, len(p) - stride, stride):
            if jump[i:i + stride].any():
                continue
            c = tuple(int(v) for v in colors[i])
            cv2.line(img, tuple(p[i]), tuple(p[i + stride]), c, thick, cv2.LINE_AA, 4)

    for cone in (result.cones if result.cones is not None else np.zeros((0, 2))):
        cx, cy = view.px(cone)[0]
        r = max(6, int(round(0.6 * scale)))  # drawn larger than life so they stay visible
        tri = np.array([[cx, cy - r], [cx - r, cy + 0.8 * r], [cx + r, cy + 0.8 * r]], np.int32)
        cv2.fillPoly(img, [tri], (0, 120, 255), cv2.LINE_AA)
        cv2.polylines(img, [tri], True, (0, 0, 0), 1, cv2.LINE_AA)

    # start and lap direction
    spawn_s = track.start_s if result.config.spawn_s is None else result.config.spawn_s
    sx, sy, heading = track.point_at(spawn_s)
    if result.config.reverse:
        heading += math.pi
    heading += math.radians(result.config.yaw_offset_deg)
    a = view.px([sx, sy])[0]
    b = view.px([sx + 12 * math.cos(heading), sy + 12 * math.sin(heading)])[0]
    cv2.arrowedLine(img, tuple(int(v) for v in a), tuple(int(v) for v in b), (255, 255, 255), 2, cv2.LINE_AA,
                    tipLength=0.35)
    cv2.circle(img, tuple(int(v) for v in a), 5, (255, 255, 255), -1, cv2.LINE_AA)
    _text(img, "start", (int(a[0]) + 8, int(a[1]) - 8), 0.45, box=True)

    interventions = [(lap.lap, i) for lap in result.laps for i in lap.interventions]
    for n, (_, iv) in enumerate(interventions, 1):
        q = tuple(int(v) for v in view.px([iv.x, iv.y])[0])
        col = _CAUSE_COLORS.get(str(iv.cause), (255, 255, 255))
        d = 7
        cv2.line(img, (q[0] - d, q[1] - d), (q[0] + d, q[1] + d), (0, 0, 0), 5, cv2.LINE_AA)
        cv2.line(img, (q[0] - d, q[1] + d), (q[0] + d, q[1] - d), (0, 0, 0), 5, cv2.LINE_AA)
        cv2.line(img, (q[0] - d, q[1] - d), (q[0] + d, q[1] + d), col, 2, cv2.LINE_AA)
        cv2.line(img, (q[0] - d, q[1] + d), (q[0] + d, q[1] - d), col, 2, cv2.LINE_AA)
        if len(interventions) <= 40:
            _text(img, str(n), (q[0] + 9, q[1] + 5), 0.45, col, box=True)

    _legend(img, w + 12, result, track, vmax, interventions)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), img):
        raise OSError(f"cannot write {out}")
    return out


def _legend(img: np.ndarray, x: int, result: RunResult, track: Track, vmax: float,
            interventions: list) -> None:
    y = 28
    cfg = result.config
    _text(img, f"{track.name}: {result.driver}", (x, y), 0.55)
    y += 22
    direction = "reverse" if cfg.reverse else "default direction"
    _text(img, f"{track.length:.0f} m, {direction}, {cfg.cones} cones", (x, y), 0.45, _MUTED)
    y += 18
    mode = "real time" if cfg.realtime else f"lock-step {cfg.control_hz:g} Hz"
    _text(img, f"limit {cfg.speed_limit_kmh:g} km/h, {mode}", (x, y), 0.45, _MUTED)
    y += 26
    for lap in result.laps:
        state = ("" if lap.completed else " (not finished)") + (" (below 0, shown as 0)" if lap.eta_clamped else "")
        _text(img, f"lap {lap.lap}: degree of autonomy {lap.eta:.1f} %{state}", (x, y), 0.5)
        y += 18
        _text(img, f"  {lap.lap_time_s:.1f} s, {lap.mean_speed_kmh:.1f} km/h, cte rms {lap.cte_rms_m:.2f} m",
              (x, y), 0.42, _MUTED)
        y += 20
    # colour bar
    y += 6
    _text(img, "cross-track error, absolute (m)", (x, y), 0.45)
    y += 10
    bar_w, bar_h = 260, 14
    ramp = _colormap(np.linspace(0, vmax, bar_w), vmax)
    img[y:y + bar_h, x:x + bar_w] = ramp[None, :, :]
    cv2.rectangle(img, (x, y), (x + bar_w - 1, y + bar_h), (255, 255, 255), 1)
    for v in np.arange(0.0, vmax + 1e-9, 1.0 if vmax <= 6 else 2.0):
        tx = x + int(round(v / vmax * (bar_w - 1)))
        cv2.line(img, (tx, y + bar_h), (tx, y + bar_h + 4), (255, 255, 255), 1)
        _text(img, f"{v:.0f}", (tx - 4, y + bar_h + 18), 0.4, _MUTED)
    y += bar_h + 36
    _text(img, f"from the {'lane' if track.lanes == 2 else 'road'} centre; full scale: half the road",
          (x, y), 0.4, _MUTED)
    y += 26
    _text(img, f"interventions: {len(interventions)}", (x, y), 0.5)
    y += 20
    for cause, col in _CAUSE_COLORS.items():
        cv2.line(img, (x + 2, y - 8), (x + 12, y + 2), col, 2, cv2.LINE_AA)
        cv2.line(img, (x + 2, y + 2), (x + 12, y - 8), col, 2, cv2.LINE_AA)
        _text(img, cause.replace("_", " "), (x + 20, y), 0.42, _MUTED)
        y += 17
    y += 6
    room = (img.shape[0] - y - 10) // 16
    for n, (lap, iv) in enumerate(interventions[:max(0, room)], 1):
        col = _CAUSE_COLORS.get(str(iv.cause), _TEXT)
        _text(img, f"{n:2d}. lap {lap}  s={iv.s:6.1f} m  t={iv.t:6.1f} s  {iv.cause}", (x, y), 0.4, col)
        y += 16
    if len(interventions) > max(0, room):
        _text(img, f"... {len(interventions) - max(0, room)} more", (x, y), 0.4, _MUTED)


# ------------------------------------------------------------------------------------------- strip & video


def annotate(event: FrameEvent, speed_unit: str = "km/h") -> np.ndarray:
    """The camera frame (BGR, 2x) with time, steering, throttle and speed written over it."""
    bgr = cv2.cvtColor(event.rgb, cv2.COLOR_RGB2BGR)
    bgr = cv2.resize(bgr, (bgr.shape[1] * 2, bgr.shape[0] * 2), interpolation=cv2.INTER_LINEAR)
    st, cmd = event.state, event.command
    steer_deg = math.degrees(st.steer)
    _text(bgr, f"t {event.t:6.1f} s  lap {event.lap}", (8, 22), 0.6, box=True)
    _text(bgr, f"steer {steer_deg:+5.1f} deg  cmd {cmd.steering:+.2f}", (8, 46), 0.6, box=True)
    pedal = f"throttle {cmd.throttle:+.2f}" if cmd.throttle >= 0 else f"brake {-cmd.throttle:.2f}"
    _text(bgr, f"{pedal}  speed {mps_to_kmh(st.speed):4.1f} {speed_unit}", (8, 70), 0.6, box=True)
    # steering bar along the bottom: centre tick, wheel angle as a filled bar
    h, w = bgr.shape[:2]
    cx, y0 = w // 2, h - 18
    cv2.rectangle(bgr, (cx - 150, y0), (cx + 150, y0 + 10), (0, 0, 0), -1)
    end = cx + int(round(150 * max(-1.0, min(1.0, steer_deg / MAX_STEERING_DEG))))
    # + steering = right (Unity's convention): the bar grows to the right
    cv2.rectangle(bgr, (min(cx, end), y0 + 2), (max(cx, end), y0 + 8), (0, 220, 255), -1)
    cv2.line(bgr, (cx, y0 - 3), (cx, y0 + 13), (255, 255, 255), 1)
    iv = event.intervention
    if iv is not None and 0.0 <= event.t - iv.t < TAKEOVER_MARK_S:  # why the car just jumped back to the road
        cv2.rectangle(bgr, (0, 0), (w - 1, h - 1), _CAUSE_COLORS.get(str(iv.cause), (60, 60, 230)), 6)
        _text(bgr, f"TAKE-OVER: {str(iv.cause).replace('_', ' ')} at {iv.t:.1f} s, car put back on the road",
              (8, 94), 0.55, (80, 80, 255), box=True)
    return bgr


#: How long after a take-over the camera overlay marks it (simulated seconds).
TAKEOVER_MARK_S = 1.5


class StripCollector:
    """Keeps one frame every ``every_s`` simulated seconds (the ``on_frame`` hook of run_scenario)."""

    def __init__(self, every_s: float = 5.0, limit: int = 48) -> None:
        self.every_s, self.limit = every_s, limit
        self.frames: list[np.ndarray] = []
        self._next = 0.0
        self._last_takeover: object = None  # every take-over gets a frame of its own

    def __call__(self, event: FrameEvent) -> None:
        new_takeover = event.intervention is not None and event.intervention is not self._last_takeover
        if (event.t >= self._next or new_takeover) and len(self.frames) < self.limit:
            self._next = event.t + self.every_s
            self._last_takeover = event.intervention
            self.frames.append(annotate(event))

    def write(self, path: str | Path, cols: int = 4) -> Path:
        if not self.frames:
            raise BadValue("no frames collected")
        h, w = self.frames[0].shape[:2]
        rows = math.ceil(len(self.frames) / cols)
        sheet = np.full((rows * (h + 4) + 4, cols * (w + 4) + 4, 3), 20, np.uint8)
        for k, f in enumerate(self.frames):
            r, c = divmod(k, cols)
            sheet[4 + r * (h + 4):4 + r * (h + 4) + h, 4 + c * (w + 4):4 + c * (w + 4) + w] = f
        out = Path(path)
        out.parent.mkdir(parents=True, exist_ok=True)
        # JPEG for .jpg (a tenth of the size); PNG at its best compression otherwise
        params = [cv2.IMWRITE_JPEG_QUALITY, 85] if out.suffix.lower() in (".jpg", ".jpeg") else \
            [cv2.IMWRITE_PNG_COMPRESSION, 9]
        if not cv2.imwrite(str(out), sheet, params):
            raise OSError(f"cannot write {out}")
        return out


class VideoRecorder:
    """Writes every telemetry frame, annotated, to a browser-playable H.264 mp4 (:mod:`tools.sim.pictures.video`)."""

    def __init__(self, path: str | Path, fps: float) -> None:
        from tools.sim.pictures.video import VideoWriter

        self.path = Path(path)
        self.fps = fps
        self._writer = VideoWriter(self.path, fps)
        self.backend = self._writer.backend

    @property
    def frames(self) -> int:
        return self._writer.frames

    def __call__(self, event: FrameEvent) -> None:
        self._writer.write(annotate(event))

    def close(self) -> None:
        self._writer.close()
