"""Frame sources for simulator stand-ins: telemetry payloads with base64 JPEG images.

Two sources: frames replayed from a recorded driving log (the real simulator's JPEGs, sent as
recorded, never re-encoded) and synthetic frames generated here. Both yield the exact payload the
Unity simulator sends (every value a string). Needs only numpy, opencv and ``protocol``.
"""

from __future__ import annotations

import base64
import itertools
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from protocol import FRAME_HEIGHT, FRAME_WIDTH, MAX_STEERING_DEG, encode_image, encode_telemetry
from protocol.datalog import find_log, read_log
from protocol.errors import BadValue
from protocol.facts import CAMERAS

log = logging.getLogger(__name__)



@dataclass(frozen=True)
class SourceFrame:
    """A ready-to-send frame: base64 JPEG plus the vehicle state that goes with it."""

    image_b64: str
    steering_deg: float
    throttle: float
    speed: float

    def payload(self, decimal: str = ".") -> dict[str, str]:
        """The ``telemetry`` payload exactly as Unity writes it."""
        return encode_telemetry(self.steering_deg, self.throttle, self.speed, self.image_b64, decimal)


def log_frames(path: Path, camera: str = "center") -> list[SourceFrame]:
    """All frames of a driving log from one camera, JPEG bytes sent as recorded."""
    if camera not in CAMERAS:
        raise BadValue(f"camera must be one of {CAMERAS}, not {camera!r}")
    samples, _ = read_log(find_log(Path(path)))  # the training pipeline's tolerant reader (numpy/stdlib only)
    frames = []
    for row in samples:
        image = getattr(row, camera)
        if image is None:
            raise BadValue(f"{row.log}:{row.line}: the log has no {camera} camera image")
        jpeg = image.read_bytes()
        frames.append(SourceFrame(base64.b64encode(jpeg).decode("ascii"), row.steering * MAX_STEERING_DEG,
                            row.throttle, row.speed))
    return frames


def synthetic_frames(n: int, seed: int = 0) -> list[SourceFrame]:
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
        frames.append(SourceFrame(encode_image(img), float(rng.uniform(-5, 5)), 0.2, float(rng.uniform(0, 30))))
    return frames


def cycle_payloads(frames: list[SourceFrame], n: int | None = None, decimal: str = ".") -> Iterator[dict[str, str]]:
    """Payloads of ``frames`` cycled (``n`` in total, or forever); each payload is built once."""
    if not frames:
        raise BadValue("no frames to send")
    payloads = [f.payload(decimal) for f in frames]
    it = itertools.cycle(payloads)
    return it if n is None else itertools.islice(it, n)
