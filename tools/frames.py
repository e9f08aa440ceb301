"""Frame sources for simulator stand-ins: telemetry payloads with base64 JPEG images.

Two sources: frames replayed from a recorded driving log (the real simulator's JPEGs, sent as
recorded, never re-encoded) and synthetic frames generated here. Both yield the exact payload the
Unity simulator sends (every value a string). Needs only numpy, opencv and ``protocol``.
"""

from __future__ import annotations

import base64
import csv
import itertools
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from protocol import FRAME_HEIGHT, FRAME_WIDTH, MAX_STEERING_DEG, encode_image, encode_telemetry

log = logging.getLogger(__name__)

LOG_NAMES = ("driving_log.csv", "Driving-Log.csv")
CAMERAS = ("center", "left", "right")


@dataclass(frozen=True)
class LogRow:
    """One row of a driving log; image paths already resolved to files next to the log."""

    center: Path
    left: Path
    right: Path
    steering: float  # normalised -1..1
    throttle: float
    brake: float
    speed: float  # as recorded (mph for the stock simulator, km/h for the paper's)


def find_log(path: Path) -> Path:
    """The CSV of a driving log given the file itself or its folder."""
    path = Path(path)
    if path.is_file():
        return path
    for name in LOG_NAMES:
        if (path / name).is_file():
            return path / name
    candidates = sorted(path.glob("*.csv"))
    if len(candidates) == 1:
        return candidates[0]
    raise FileNotFoundError(f"no driving log ({' or '.join(LOG_NAMES)}) in {path}")


def _resolve_image(recorded: str, log_dir: Path) -> Path:
    """Only the file name of a recorded path is meaningful: the image is in IMG/ next to the log."""
    name = recorded.strip().replace("\\", "/").rsplit("/", 1)[-1]
    for candidate in (log_dir / "IMG" / name, log_dir / name):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"image {name!r} (recorded as {recorded.strip()!r}) not found in {log_dir / 'IMG'}")


def _number(text: str) -> float | None:
    try:
        return float(text.strip().replace(",", "."))
    except ValueError:
        return None


def read_driving_log(path: Path) -> list[LogRow]:
    """Read a Udacity-format driving log, tolerant of what real recordings contain.

    Accepts Windows absolute paths, ``", "`` separators, an optional header row, and resolves each image
    by its file name in ``IMG/`` next to the log.
    """
    csv_path = find_log(Path(path))
    rows: list[LogRow] = []
    with csv_path.open(newline="", encoding="utf-8-sig") as fh:
        for lineno, fields in enumerate(csv.reader(fh, skipinitialspace=True), start=1):
            if not fields or all(not f.strip() for f in fields):
                continue
            if len(fields) < 7:
                raise ValueError(f"{csv_path}:{lineno}: expected 7 columns, got {len(fields)}")
            numbers = [_number(f) for f in fields[3:7]]
            if any(n is None for n in numbers):
                if lineno == 1:  # header row
                    continue
                raise ValueError(f"{csv_path}:{lineno}: non-numeric steering/throttle/brake/speed {fields[3:7]}")
            steering, throttle, brake, speed = (float(n) for n in numbers)  # type: ignore[arg-type]
            center, left, right = (_resolve_image(f, csv_path.parent) for f in fields[:3])
            rows.append(LogRow(center, left, right, steering, throttle, brake, speed))
    if not rows:
        raise ValueError(f"{csv_path}: no rows")
    return rows


@dataclass(frozen=True)
class Frame:
    """A ready-to-send frame: base64 JPEG plus the vehicle state that goes with it."""

    image_b64: str
    steering_deg: float
    throttle: float
    speed: float

    def payload(self, decimal: str = ".") -> dict[str, str]:
        """The ``telemetry`` payload exactly as Unity writes it."""
        return encode_telemetry(self.steering_deg, self.throttle, self.speed, self.image_b64, decimal)


def log_frames(path: Path, camera: str = "center") -> list[Frame]:
    """All frames of a driving log from one camera, JPEG bytes sent as recorded."""
    if camera not in CAMERAS:
        raise ValueError(f"camera must be one of {CAMERAS}, not {camera!r}")
    frames = []
    for row in read_driving_log(path):
        jpeg = getattr(row, camera).read_bytes()
        frames.append(Frame(base64.b64encode(jpeg).decode("ascii"), row.steering * MAX_STEERING_DEG,
                            row.throttle, row.speed))
    return frames


def synthetic_frames(n: int, seed: int = 0) -> list[Frame]:
    """``n`` generated 320x160 road-like frames (sky, grey road, lane edges, noise), JPEG quality 75."""
    rng = np.random.default_rng(seed)
    frames = []
    ys, xs = np.mgrid[0:FRAME_HEIGHT, 0:FRAME_WIDTH]
    for i in range(n):
        img = np.empty((FRAME_HEIGHT, FRAME_WIDTH, 3), np.uint8)
        horizon = FRAME_HEIGHT // 2 + int(rng.integers(-8, 9))
        img[:horizon] = (120, 170, 230)
        img[horizon:] = (70, 120, 60)
        centre = FRAME_WIDTH / 2 + 40 * np.sin(i / 10.0)
        half = 20 + (ys - horizon).clip(0) * 1.6
        road = (ys >= horizon) & (np.abs(xs - centre) < half)
        img[road] = (110, 110, 110)
        edge = road & (np.abs(np.abs(xs - centre) - half) < 3)
        img[edge] = (230, 230, 230)
        noise = rng.integers(-12, 13, img.shape, dtype=np.int16)
        img = (img.astype(np.int16) + noise).clip(0, 255).astype(np.uint8)
        frames.append(Frame(encode_image(img), float(rng.uniform(-5, 5)), 0.2, float(rng.uniform(0, 30))))
    return frames


def cycle_payloads(frames: list[Frame], n: int | None = None, decimal: str = ".") -> Iterator[dict[str, str]]:
    """Payloads of ``frames`` cycled (``n`` in total, or forever); each payload is built once."""
    if not frames:
        raise ValueError("no frames to send")
    payloads = [f.payload(decimal) for f in frames]
    it = itertools.cycle(payloads)
    return it if n is None else itertools.islice(it, n)
