"""``--workers N``: N server processes sharing one listening socket, for several simulators at once.

Why: an eventlet server runs on one core, and each frame costs it ~0.75 ms of CPU (JPEG decode and
inference ~0.45 ms, python-socketio/engine.io/eventlet ~0.25 ms), so one process tops out near
1,300 telemetry/s however many simulators are connected. A native thread pool does not help (the work
is interleaved with Python that needs the GIL); separate processes do. The parent opens the socket,
forks the workers (each loads its own ONNX Runtime session after the fork), and the kernel hands each
new connection to one of them. A connection lives in one worker, so per-client state is unchanged.

Limitation: Engine.IO long-polling needs every request of a session to reach the same process, so
workers accept the WebSocket transport only: the Unity simulator (WebSocket only anyway) and modern
clients configured with ``transports=["websocket"]``. One worker (the default) serves every client.
POSIX only (fork).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import socket
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from drive_server.observing.stats import FaultCounters, load_stats, summarize, summary_line
from drive_server.serving.model import SteeringModel
from drive_server.wire import listen
from drive_server.wire.server import DriveServer
from drive_server.wire.server_config import ServerConfig, stats_document
from drive_server.wire.transport import TransportTuning
from protocol.runrecords import write_json

log = logging.getLogger(__name__)


def _run_worker(index: int, sock: socket.socket, make_server: Callable[[ServerConfig], DriveServer],
                config: ServerConfig) -> int:
    """Body of one forked worker: serve until SIGTERM, then hand the statistics back."""
    for handler in logging.getLogger().handlers:
        fmt = (handler.formatter._fmt if handler.formatter else None) or "%(message)s"
        handler.setFormatter(logging.Formatter(fmt.replace("%(name)s", f"%(name)s[w{index}]"), "%H:%M:%S"))
    server = make_server(config)
    server.adopt(sock)
    server.serve(announce=False)
    return 0


def serve_workers(workers: int, sock: socket.socket, model: SteeringModel, config: ServerConfig,
                  make_server: Callable[[ServerConfig], DriveServer], transport: TransportTuning) -> int:
    """Fork ``workers`` servers on ``sock`` and supervise them; returns the exit code for the CLI.

    SIGINT/SIGTERM stop the workers; their statistics are merged into ``config.stats_json``. If a worker
    dies on its own, the others are stopped too (exit code 1): a half-served port is worse than none.
    """
    tmp = tempfile.TemporaryDirectory(prefix="drive_server_workers_")
    pids: dict[int, int] = {}
    for i in range(workers):
        worker_config = replace(config, transports=("websocket",), stats_json=None,
                                stats_dump=Path(tmp.name) / f"worker{i}.npz")
        pid = os.fork()
        if pid == 0:  # child
            code = 1
            try:
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                signal.signal(signal.SIGTERM, signal.SIG_DFL)
                code = _run_worker(i, sock, make_server, worker_config)
            except BaseException:
                logging.getLogger(__name__).exception("worker %d failed", i)
            finally:
                logging.shutdown()
                os._exit(code)
        pids[pid] = i
    stop = False

    def request_stop(*_: object) -> None:
        nonlocal stop
        stop = True

    previous = {s: signal.signal(s, request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    log.info("listening on %s (%d worker processes, WebSocket transport only)", listen.url(sock), workers)
    code = 0
    try:
        while not stop:
            pid, status = os.waitpid(-1, os.WNOHANG)
            if pid:
                log.error("worker %d exited unexpectedly (status %d): stopping", pids.pop(pid, -1), status)
                code = 1
                break
            time.sleep(0.2)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        _stop_all(pids)
        sock.close()
        stats = [s for i in range(workers) if (Path(tmp.name) / f"worker{i}.npz").is_file()
                 for s in load_stats(Path(tmp.name) / f"worker{i}.npz")]
        log.info("stopped: %s", summary_line(summarize(stats)))
        faults = FaultCounters()
        for i in range(workers):
            dump = (Path(tmp.name) / f"worker{i}.npz").with_suffix(".faults.json")
            if dump.is_file():
                faults.merge(json.loads(dump.read_text(encoding="utf-8")))
        if config.stats_json is not None:
            write_json(config.stats_json, stats_document(model, transport, stats, workers=workers,
                                                         faults=faults.as_dict(), limits=config.limits), sort_keys=True)
        tmp.cleanup()
    return code


def _stop_all(pids: dict[int, int], timeout: float = 10.0) -> None:
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGTERM)
    deadline = time.monotonic() + timeout
    while pids and time.monotonic() < deadline:
        pid, _ = os.waitpid(-1, os.WNOHANG)
        if pid:
            pids.pop(pid, None)
        else:
            time.sleep(0.05)
    for pid in pids:  # still running: it hung
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
