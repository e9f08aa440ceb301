"""Decode every frame once into a uint8 array at the network's resolution.

Training looks at each frame ~64 x epochs times; decoding a JPEG costs far more than the rest of
its augmentation, so frames are decoded once, at libjpeg's reduced scale chosen by the serving rule
(``jpeg_reduction``), and passed through THE shared ``frame_to_network_image`` (crop, resize,
colour). 10,000 samples x 3 cameras at 64x64 take 370 MB.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drive_server.serving.contract import PreprocessContract
from drive_server.serving.preprocess import frame_to_network_image, jpeg_reduction
from protocol.datalog import Sample
from protocol.errors import BadValue, ProtocolError
from protocol.facts import CAMERAS
from protocol.jpeg import read_jpeg_file

log = logging.getLogger(__name__)

class FrameError(BadValue):
    """A frame file could not be decoded as a 320x160 image."""


def load_frame(path: Path, reduce: int = 1) -> np.ndarray:
    """Decode an image file to RGB uint8 at 1/``reduce`` size: THE decode the drive server uses."""
    try:
        return read_jpeg_file(path, reduce)
    except OSError as exc:
        raise FrameError(f"{path}: {exc.strerror or exc}") from None
    except ProtocolError as exc:
        raise FrameError(str(exc)) from None


@dataclass
class FrameCache:
    """``frames[camera, sample]`` is the network-size uint8 image (contract colour) of that camera."""

    frames: np.ndarray  # (cameras, n, height, width, 3) uint8
    cameras: tuple[str, ...]
    contract: PreprocessContract
    valid: np.ndarray  # (n,) bool: False where a frame failed to decode
    errors: list[str]

    @property
    def nbytes(self) -> int:
        return int(self.frames.nbytes)


def build_cache(samples: Sequence[Sample], contract: PreprocessContract, cameras: Sequence[str] = CAMERAS,
                workers: int = 2, progress: Callable[[int, int], None] | None = None,
                reduce: int | None = None) -> FrameCache:
    """Decode the given cameras of every sample (side frames of one-camera samples stay black).

    ``progress(done, total)`` is called after every chunk of samples. ``reduce`` overrides the serving
    rule's JPEG decode scale (tests compare against full decodes).
    """
    cams = tuple(c for c in CAMERAS if c in cameras)
    n = len(samples)
    frames = np.zeros((len(cams), n, contract.height, contract.width, 3), np.uint8)
    valid = np.ones(n, dtype=bool)
    errors: list[str] = []
    reduce = jpeg_reduction(contract) if reduce is None else reduce

    def work(i: int) -> None:
        s = samples[i]
        for c, cam in enumerate(cams):
            path = getattr(s, cam)
            if path is None:
                continue
            try:
                frames[c, i] = frame_to_network_image(load_frame(path, reduce), contract)
            except FrameError as exc:
                valid[i] = False
                errors.append(f"{s.log.name}:{s.line}: {exc}")
                return

    chunk = 256
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        for start in range(0, n, chunk):
            list(pool.map(work, range(start, min(n, start + chunk))))
            if progress is not None:
                progress(min(n, start + chunk), n)
    if errors:
        log.warning("%d samples with unreadable frames skipped; first: %s", len(errors), errors[0])
    return FrameCache(frames, cams, contract, valid, errors)
