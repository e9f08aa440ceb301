"""Videos a browser plays: H.264 (yuv420p, +faststart) through PyAV, the one writer of ``rbc video`` and
``rbc sim --video``.

OpenCV's ``mp4v`` (MPEG-4 Part 2) files play in desktop players but not in Chrome, Firefox or Safari.
PyAV (the ``video`` extra) is a maintained FFmpeg binding whose wheels carry libx264. Without it the
writer falls back to OpenCV's mp4v and says so once. Frames go to a hidden temporary file that is
renamed when the video is closed, so an interrupted run never leaves a truncated ``.mp4`` behind.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

if TYPE_CHECKING:
    from av.container import OutputContainer
    from av.video.stream import VideoStream

log = logging.getLogger(__name__)

H264 = "h264 (PyAV, libx264)"
MP4V = "mp4v (OpenCV; browsers will not play it)"


def h264_available() -> bool:
    try:
        import av
    except ImportError:
        return False
    return "libx264" in av.codecs_available


class VideoWriter:
    """``write(bgr)`` frame by frame, then ``close()``; the size is taken from the first frame."""

    def __init__(self, path: str | Path, fps: float, prefer_h264: bool = True) -> None:
        self.path = Path(path)
        self.fps = float(fps)
        self.frames = 0
        self.backend = H264 if prefer_h264 and h264_available() else MP4V
        if self.backend == MP4V:
            log.warning("PyAV with libx264 is not installed: writing %s with OpenCV's mp4v codec, which browsers "
                        "do not play (for H.264: pip install -e \".[video]\")", self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.stem}.part{self.path.suffix or '.mp4'}")
        self._av: tuple[OutputContainer, VideoStream] | None = None  # the H.264 writer, once open
        self._cv: cv2.VideoWriter | None = None  # the mp4v writer, once open
        self._size: tuple[int, int] | None = None

    def _open(self, w: int, h: int) -> None:
        self._size = (w - w % 2, h - h % 2)  # yuv420p needs even sizes
        if self.backend == H264:
            from fractions import Fraction

            import av

            out = av.open(str(self._tmp), mode="w", format="mp4", options={"movflags": "+faststart"})
            rate = Fraction(self.fps).limit_denominator(1000)
            stream = out.add_stream("libx264", rate=rate, options={"crf": "23", "preset": "veryfast"})
            stream.width, stream.height = self._size
            stream.pix_fmt = "yuv420p"
            self._av = out, stream
        else:
            self._cv = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter.fourcc(*"mp4v"), self.fps, self._size)
            if not self._cv.isOpened():
                raise OSError(f"OpenCV cannot write mp4 video to {self.path} (no mp4v encoder in this build)")

    def write(self, bgr: np.ndarray) -> None:
        if self._av is None and self._cv is None:
            self._open(bgr.shape[1], bgr.shape[0])
        assert self._size is not None
        frame = np.ascontiguousarray(bgr[:self._size[1], :self._size[0]])
        if self._av is not None:
            import av

            out, stream = self._av
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="bgr24")):
                out.mux(packet)
        elif self._cv is not None:
            self._cv.write(frame)
        self.frames += 1

    def close(self) -> Path | None:
        """Finish the file and move it into place; returns its path (None when no frame was written)."""
        if self._av is not None:
            out, stream = self._av
            for packet in stream.encode():
                out.mux(packet)
            out.close()
        elif self._cv is not None:
            self._cv.release()
        else:
            return None
        self._av = self._cv = None
        os.replace(self._tmp, self.path)
        return self.path

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
