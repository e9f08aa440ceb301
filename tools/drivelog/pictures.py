"""Pictures of a closed loop on a recording: a strip of the synthesized views, and the offset over time.

Drawn with OpenCV and the project's text helper, so ``rbc drive-log`` needs no plotting package.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from protocol.errors import BadValue
from protocol.jpeg import read_jpeg_file
from tools.drivelog.loop import LoopResult, Snapshot
from tools.drivelog.path import RecordedDrive
from tools.sim.pictures.text import draw_text

_RED, _GREY, _BLUE, _WHITE = (60, 60, 230), (150, 150, 150), (200, 120, 40), (245, 245, 245)
_PERSON = (225, 225, 255)  # light pink (BGR)


def write_strip(result: LoopResult, path: Path, columns: int = 4) -> Path:
    """The kept views (RGB) in a grid, each labelled with its offset, heading and steering (BGR JPEG/PNG)."""
    shots = sorted(result.snapshots, key=lambda s: s.step)
    if not shots:
        raise BadValue("no views were kept")
    h, w = shots[0].view.shape[:2]
    rows = -(-len(shots) // columns)
    sheet = np.zeros((rows * h, min(columns, len(shots)) * w, 3), np.uint8)
    for k, shot in enumerate(shots):
        tile = cv2.cvtColor(shot.view, cv2.COLOR_RGB2BGR)
        label = f"#{shot.step}  e {shot.offset_m:+.2f} m  psi {shot.heading_deg:+.1f}  steer {shot.steering:+.2f}"
        draw_text(tile, label, (4, 14), px=11, box=True)
        if shot.takeover:
            cv2.rectangle(tile, (1, 1), (w - 2, h - 2), _RED, 3)
            draw_text(tile, "take-over: left the lane", (4, h - 28), px=11, color=_RED, box=True)
        if shot.limits is not None and result.rules.lane == "road":
            draw_text(tile, f"road edges {shot.limits[0] - shot.offset_m - result.rules.half_width_m:+.1f} / "
                            f"{shot.limits[1] - shot.offset_m + result.rules.half_width_m:+.1f} m",
                      (4, 30), px=11, box=True)
        r, c = divmod(k, columns)
        sheet[r * h:(r + 1) * h, c * w:(c + 1) * w] = tile
    _write(path, sheet)
    return path


def write_takeover_strips(result: LoopResult, log: RecordedDrive, folder: Path, columns: int = 4) -> list[Path]:
    """One picture per take-over (``folder/takeover-NN.jpg``): the car's views in the seconds before it (top,
    the last one the take-over's) above the recorded frames of the same moments (what the driver saw), each
    labelled with its time before the take-over, offset from the driver's path, heading error and steering;
    the pictures to tell the model's faults from the measure's (``drive(history_s=...)`` keeps the views)."""
    if len(result.before_takeovers) != result.interventions:
        raise BadValue("the views before the take-overs were not kept (drive with history_s > 0)")
    times = np.concatenate([[0.0], np.cumsum(log.dt[:-1])])
    paths = []
    for k, (takeover, views) in enumerate(zip(result.takeovers, result.before_takeovers, strict=True), 1):
        chosen = _spread(views, columns)
        if not chosen:
            continue
        h, w = chosen[0].view.shape[:2]
        sheet = np.zeros((2 * h, len(chosen) * w, 3), np.uint8)
        for c, shot in enumerate(chosen):
            ahead = times[shot.step] - times[takeover.frame]
            car = cv2.cvtColor(shot.view, cv2.COLOR_RGB2BGR)
            draw_text(car, f"{ahead:+.1f} s  e {shot.offset_m:+.2f} m  psi {shot.heading_deg:+.1f}  "
                           f"steer {shot.steering:+.2f}", (4, 14), px=11, box=True)
            if shot.takeover:
                cv2.rectangle(car, (1, 1), (w - 2, h - 2), _RED, 3)
            recorded = cv2.resize(cv2.cvtColor(read_jpeg_file(log.frames[shot.step]), cv2.COLOR_RGB2BGR), (w, h))
            draw_text(recorded, f"the driver's frame #{shot.step}, steer {log.steering[shot.step]:+.2f}", (4, 14),
                      px=11, box=True)
            sheet[:h, c * w:(c + 1) * w] = car
            sheet[h:, c * w:(c + 1) * w] = recorded
        paths.append(folder / f"takeover-{k:02d}.jpg")
        _write(paths[-1], sheet)
    return paths


def _spread(views: list[Snapshot], n: int) -> list[Snapshot]:
    """``n`` of ``views`` evenly spread in order, the last always among them."""
    if len(views) <= n:
        return list(views)
    return [views[int(round(j))] for j in np.linspace(0, len(views) - 1, n)]


def write_offset_plot(result: LoopResult, path: Path, title: str, size: tuple[int, int] = (1000, 300)) -> Path:
    """Lateral offset from the recorded path at every step; where the car leaves the lane (grey), take-overs
    in red."""
    width, height = size
    left, right, top, bottom = 56, 12, 28, 30
    img = np.full((height, width, 3), 255, np.uint8)
    n = max(2, len(result.offsets))
    limits = result.limits if result.limits is not None and len(result.limits) else None
    limit = float(np.max(np.abs(limits))) if limits is not None else result.rules.max_offset_m
    span = max(limit * 1.1, float(np.max(np.abs(result.offsets))) if len(result.offsets) else 0.0, 0.5)

    def xy(i: float, e: float) -> tuple[int, int]:
        x = left + (width - left - right) * i / (n - 1)
        y = top + (height - top - bottom) * (0.5 - e / (2 * span))
        return int(round(x)), int(round(y))

    if result.person is not None and result.person.any():  # the stretches a person drove after a take-over
        edges = np.flatnonzero(np.diff(np.concatenate([[0], result.person.astype(np.int8), [0]])))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            cv2.rectangle(img, (xy(start, 0.0)[0], top), (xy(stop - 1, 0.0)[0], height - bottom), _PERSON, -1)
    if limits is not None and len(limits) > 1:
        for side in (0, 1):
            pts = np.array([xy(i, e) for i, e in enumerate(limits[:, side])], np.int32)
            cv2.polylines(img, [pts], False, _GREY, 1, cv2.LINE_AA)
    cv2.line(img, xy(0, 0), xy(n - 1, 0), (210, 210, 210), 1)
    if len(result.offsets) > 1:
        pts = np.array([xy(i, e) for i, e in enumerate(result.offsets)], np.int32)
        cv2.polylines(img, [pts], False, _BLUE, 1, cv2.LINE_AA)
    for t in result.takeovers:
        cv2.circle(img, xy(t.step, t.offset_m), 4, _RED, -1, cv2.LINE_AA)
    for e in (-limit, 0.0, limit):
        draw_text(img, f"{e:+.1f} m", (4, xy(0, e)[1] + 4), px=11, color=(60, 60, 60))
    lane = "road's edges" if result.rules.lane == "road" else f"{result.rules.max_offset_m:g} m from the driver's line"
    draw_text(img, f"grey: where the car leaves the lane ({lane})", (width - 330, 18), px=11, color=(90, 90, 90))
    draw_text(img, title, (left, 18), px=13, color=(30, 30, 30))
    off_road = f", and {result.off_road_s:.0f} s where the driver left the road" if result.off_road_s else ""
    off_road += f", and {result.reversing_s:.0f} s where the driver reversed" if result.reversing_s else ""
    draw_text(img, f"step of the loop (0 .. {n - 1}, one per recorded frame interval); red: take-overs "
                   f"({result.interventions}); pink: a person drives ({result.rules.handback_s:g} s each"
                   f"{off_road})",
              (left, height - 8),
              px=11, color=(60, 60, 60))
    _write(path, img)
    return path


def _write(path: Path, bgr: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{path.suffix}")
    if not cv2.imwrite(str(tmp), bgr):
        raise OSError(f"{path}: could not write the picture")
    tmp.replace(path)
