"""``drive_server --record DIR``: every frame the server answered, with the command it sent, as a Udacity log.

Like Udacity's ``drive.py FOLDER``, but off the drive loop: the Socket.IO handler only puts the frame's
base64 text and the command on a bounded queue (a microsecond); a background thread decodes the base64
and writes ``IMG/center_<time>.jpg`` (the received JPEG bytes, not re-encoded) and one ``driving_log.csv``
row through :mod:`protocol.datalog_writer`, so ``rbc train`` and ``rbc video`` read the recording like any
other. With a misbehaviour monitor on, each frame's score, one-second mean and state go to ``monitor.csv`` beside
the log (frame name first), so the Udacity log keeps its seven columns.
If the disk cannot keep up, frames are dropped and counted rather than slowing the car; a full
disk or an unwritable folder is logged (at most every few seconds) and counted, and the server drives on.
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import datetime as dt
import logging
import os
import queue
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from protocol import SteerCommand
from protocol.datalog_writer import IMAGE_DIR, LOG_NAME, LogWriter, frame_name, last_row_stamp

if TYPE_CHECKING:
    from drive_server.serving.client_monitor import MonitorReading

log = logging.getLogger(__name__)

#: The monitor's side file: one row per recorded frame that the monitor scored.
MONITOR_LOG = "monitor.csv"
MONITOR_HEADER = "frame,score,mean,state\n"
#: Frames waiting for the disk before new ones are dropped: ~68 s at 15 Hz, at most ~21 MB of base64.
QUEUE_FRAMES = 1024
#: At most one warning about failed writes in this many seconds.
WARN_INTERVAL_S = 5.0
#: The writer sleeps this long whenever it has emptied the queue, then writes what came in one burst: a
#: few wake-ups a second instead of one per frame, so it rarely competes with the drive loop for the GIL.
BATCH_S = 0.05
#: Nice value of the writer thread (Linux schedules threads individually): it gets the CPU the drive loop
#: leaves idle.
WRITER_NICE = 19


#: One queued frame: (time.time(), its JPEG in base64, steering, throttle, speed, the monitor's reading or None).
_Frame = tuple[float, str, float, float, float, "MonitorReading | None"]


@dataclass
class RecorderCounts:
    received: int = 0  # frames handed to the recorder
    recorded: int = 0  # rows written
    dropped: int = 0  # queue full: the disk (or the low-priority writer thread) could not keep up
    failed: int = 0  # a write failed (disk full, permission, bad base64) or recording was off


class Recorder:
    """Writes (frame, command, speed) triples on a background thread; ``record`` never blocks or raises."""

    def __init__(self, folder: Path, queue_frames: int = QUEUE_FRAMES) -> None:
        self.folder = Path(folder)
        self.counts = RecorderCounts()
        self.error: str | None = None
        self._queue: queue.Queue[_Frame | None] = queue.Queue(maxsize=max(1, queue_frames))
        self._last_warning = -float("inf")
        self._writer: LogWriter | None = None
        self._last_ms = 0
        self._monitor_log: TextIO | None = None  # opened on the first frame with a monitor reading
        try:
            (self.folder / IMAGE_DIR).mkdir(parents=True, exist_ok=True)
            self._images = (self.folder / IMAGE_DIR).resolve()
            previous = last_row_stamp(self.folder / LOG_NAME)  # appending: new frame names sort after old ones
            if previous is not None:
                self._last_ms = int(previous.timestamp() * 1000)
            self._writer = LogWriter(self.folder / LOG_NAME)
        except OSError as exc:
            self.error = f"cannot record to {self.folder}: {exc.strerror or exc}"
            log.error("%s; driving on without recording", self.error)
            self._thread = None
            return
        self._thread = threading.Thread(target=self._run, name="drive-recorder", daemon=True)
        self._thread.start()
        log.info("recording every answered frame to %s", self.folder / LOG_NAME)

    # -- the drive loop's side -----------------------------------------------------------------------
    def record(self, image_b64: str, command: SteerCommand, speed: float,
               monitor: MonitorReading | None = None) -> None:
        """Queue one answered frame (called in the Socket.IO handler, after the reply went out); ``monitor``: the
        monitor's reading of it, if one scored it."""
        self.counts.received += 1
        if self._thread is None:
            self.counts.failed += 1
            return
        try:
            self._queue.put_nowait((time.time(), image_b64, command.steering, command.throttle, speed, monitor))
        except queue.Full:
            self.counts.dropped += 1

    # -- the writer thread ---------------------------------------------------------------------------
    def _run(self) -> None:
        with contextlib.suppress(OSError, AttributeError):  # not Linux, or not allowed: normal priority
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), WRITER_NICE)
        while True:
            if self._queue.empty():
                time.sleep(BATCH_S)
            item = self._queue.get()
            if item is None:
                return
            try:
                self._write(*item)
            except (OSError, ValueError, binascii.Error) as exc:
                self.counts.failed += 1
                self._warn(exc)

    def _write(self, when: float, image_b64: str, steering: float, throttle: float, speed: float,
               monitor: MonitorReading | None = None) -> None:
        ms = max(int(when * 1000), self._last_ms + 1)  # unique, increasing names even at 1,000 frames/s
        self._last_ms = ms
        name = frame_name("center", dt.datetime.fromtimestamp(ms / 1000))
        path = self._images / name
        data = base64.b64decode(image_b64, validate=True)
        assert self._writer is not None
        try:
            path.write_bytes(data)
            # the log's columns as the simulator writes them: throttle 0..1 and brake 0..1, from the sent -1..1
            self._writer.write([str(path)], steering, max(0.0, throttle), max(0.0, -throttle), speed)
        except OSError:
            path.unlink(missing_ok=True)  # a full disk: no row, and no cut-off image without one
            raise
        self.counts.recorded += 1
        if monitor is not None:
            if self._monitor_log is None:
                side = self.folder / MONITOR_LOG
                new = not side.exists() or side.stat().st_size == 0
                self._monitor_log = side.open("a", encoding="utf-8", newline="")
                if new:
                    self._monitor_log.write(MONITOR_HEADER)
            self._monitor_log.write(f"{name},{monitor.score:.6g},{monitor.mean:.6g},{monitor.level.label}\n")

    def _warn(self, exc: BaseException) -> None:
        now = time.monotonic()
        if now - self._last_warning >= WARN_INTERVAL_S:
            self._last_warning = now
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            self.error = f"recording to {self.folder} failed: {reason}"
            log.warning("%s (%d frames not recorded so far; the server drives on)", self.error, self.counts.failed)

    # -- shutdown --------------------------------------------------------------------------------------
    def close(self, timeout: float = 30.0) -> RecorderCounts:
        """Write what is queued (up to ``timeout`` seconds), close the log, log the counts."""
        if self._thread is not None:
            with contextlib.suppress(queue.Full):  # a stuck disk: give up after ``timeout``
                self._queue.put(None, timeout=timeout)
            self._thread.join(timeout)
            self._thread = None
        if self._monitor_log is not None:
            with contextlib.suppress(OSError):
                self._monitor_log.close()
            self._monitor_log = None
        if self._writer is not None:
            try:
                self._writer.close()
            except OSError as exc:
                self._warn(exc)
            self._writer = None
        c = self.counts
        log.info("recorded %d of %d answered frames to %s (%d dropped: the writer could not keep up; %d failed)",
                 c.recorded, c.received, self.folder, c.dropped, c.failed)
        return c
