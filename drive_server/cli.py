"""``drive_server``: serve an ONNX steering model to the simulator (Unity or headless) on port 4567.

The model is loaded and checked BEFORE the server listens, so a bad file ends the command at once
with exit code 2 and one line saying what is wrong, instead of a simulator that never moves.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import cv2

from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
from drive_server.serving.control import ControlLaw
from drive_server.serving.guard import FallbackPolicy
from drive_server.serving.model import InferenceConfig, ModelError, SteeringModel
from drive_server.serving.models_dir import default_model_path
from drive_server.serving.monitor import MonitorError
from drive_server.serving.pipeline import DriveConfig
from drive_server.wire import listen
from drive_server.wire.limits import WireLimits
from drive_server.wire.server_config import ServerConfig
from protocol import SpeedUnit
from protocol.errors import BadValue, UserError
from protocol.helpformat import DefaultsHelpFormatter

if TYPE_CHECKING:
    import socket

log = logging.getLogger("drive_server")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="drive_server", description=__doc__.splitlines()[0].split(": ", 1)[1],
                                formatter_class=DefaultsHelpFormatter)
    p.add_argument("--model", type=Path, default=None,
                   help="ONNX model (default: the bundled models/pretrained/unity.onnx, trained on real Unity frames)")
    server = ServerConfig  # the defaults, defined once
    p.add_argument("--host", default=server.host,
                   help="interface to listen on (default: localhost only; IPv6 such as ::1 works; another "
                        "address exposes the car and its camera to the network, with a warning)")
    p.add_argument("--port", type=int, default=server.port,
                   help="port, 0..65535 (default 4567, the simulator's; 0 = any free); one owner per port")
    drive, law, inference, fallback = DriveConfig, ControlLaw, InferenceConfig, FallbackPolicy  # the defaults
    p.add_argument("--speed-limit", type=float, default=law.speed_limit_kmh,
                   help="speed limit in km/h of the throttle/brake control law "
                        "(v_l of Eq. 14; default %(default)s)")
    p.add_argument("--steer-limit", type=float, default=law.steer_limit_deg,
                   help="steering limit in degrees: scales the model's -1..1 output (delta of Eq. 14; "
                        "default %(default)s)")
    p.add_argument("--tau", type=float, default=law.tau,
                   help="how hard the throttle/brake law answers, 0..1 (tau of Eq. 14; default %(default)s)")
    p.add_argument("--smooth", dest="smoothing", type=float, default=drive.smoothing, metavar="ALPHA",
                   help="smooth each client's steering over time: every frame sends ALPHA of the model's new output "
                        "and 1 - ALPHA of that client's last command, 0 < ALPHA <= 1, 1: off (default: what the "
                        "model's metadata asks for, 0.5 for the bundled unity.onnx; off for a model without)")
    p.add_argument("--gain", type=float, default=drive.gain, metavar="G",
                   help="multiply the network's steering by G (0.1..2) before it is clamped, smoothed and sent "
                        "(default: what the model's metadata asks for, 1.5 for the bundled unity.onnx; 1 for a "
                        "model without)")
    p.add_argument("--speed-unit", "--telemetry-speed-unit", dest="telemetry_speed_unit",
                   choices=[u.value for u in SpeedUnit], default=drive.speed_unit.value,
                   help="unit of the telemetry speed: mph like the stock Udacity simulator, or kmh like the paper's")
    monitor = MonitorPolicy  # the defaults, defined once
    p.add_argument("--monitor", choices=[m.value for m in MonitorMode], default=monitor.mode.value,
                   help="the model's misbehaviour monitor (if its file carries one): off; warn: score every frame "
                        "and log, show and record warnings and alarms; act: also slow the car on a warning and "
                        "brake to a stop on an alarm, until the score falls (default %(default)s)")
    p.add_argument("--monitor-slow", type=float, default=monitor.slow_factor, metavar="FACTOR",
                   help="with --monitor act, the speed limit on a warning is FACTOR times --speed-limit "
                        "(default %(default)s)")
    p.add_argument("--threads", type=int, default=inference.threads,
                   help="ONNX Runtime intra-op threads (default %(default)s)")
    p.add_argument("--provider", default=inference.provider,
                   help="ONNX Runtime execution provider (default %(default)s)")
    p.add_argument("--stats-json", type=Path, default=None, help="write latency statistics here at exit")
    p.add_argument("--log-every", type=float, default=server.log_every_s,
                   help="seconds between one-line latency summaries (0: only at exit)")
    p.add_argument("--hold-frames", type=int, default=fallback.hold_frames,
                   help="malformed frames answered with the last good command before a controlled stop "
                        "(default %(default)s)")
    p.add_argument("--workers", type=int, default=1,
                   help="server processes sharing the port (several simulators at once; WebSocket transport "
                        "only when > 1; POSIX only). Default 1")
    p.add_argument("--ping-interval", type=float, default=server.ping_interval_s,
                   help="seconds between the server's pings (default %(default)s)")
    p.add_argument("--dashboard", action=argparse.BooleanOptionalAction, default=None,
                   help="serve the read-only live view at http://HOST:PORT/ (default: on when listening on "
                        "localhost, off otherwise: it shows the camera to anyone who can connect)")
    p.add_argument("--record", type=Path, default=None, metavar="DIR",
                   help="save every answered frame and the command sent as a Udacity-format log in DIR "
                        "(driving_log.csv + IMG/), written off the drive loop (like Udacity's drive.py FOLDER)")
    limits = WireLimits  # the defaults, defined once
    p.add_argument("--max-connections", type=int, default=limits.max_connections,
                   help="open connections at most; then the oldest one still sending its headers is closed, "
                        "else the WebSocket silent longest (past --idle-evict), else the new one is refused "
                        "(default %(default)s)")
    p.add_argument("--header-timeout", type=float, default=limits.header_timeout_s,
                   help="seconds a connection has to send its request headers (default %(default)s)")
    p.add_argument("--idle-evict", type=float, default=limits.idle_evict_s, metavar="S",
                   help="at the connection cap, a WebSocket that has sent nothing for S seconds gives its slot "
                        "to a new client (default %(default)s)")
    p.add_argument("--max-pending", type=int, default=limits.max_pending_replies,
                   help="replies queued for a client that does not read them before it is disconnected "
                        "(default %(default)s)")
    p.add_argument("--stock-transport", action="store_true",
                   help="disable the WebSocket transport tuning (for comparison benchmarks)")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    p.add_argument("--version", action="version", version=f"drive_server {_version()}",
                   help="print the version and exit")
    return p


def _dashboard_wanted(args: argparse.Namespace, sock: socket.socket) -> bool:
    """On by default on localhost only; one process's view of its own clients, so not with --workers."""
    wanted = listen.is_local(sock.getsockname()[0]) if args.dashboard is None else args.dashboard
    if wanted and args.workers > 1:
        if args.dashboard:
            log.warning("--dashboard is not available with --workers > 1 (each worker sees only its own clients)")
        return False
    return wanted


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("robust-behavioral-cloning")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s", datefmt="%H:%M:%S")

    def fail(problem: str | UserError) -> int:
        """One line on stderr, with the error's hint, and exit code 2 (only UserErrors come here: a bug raises)."""
        hint = problem.hint if isinstance(problem, UserError) else ""
        print(f"drive_server: error: {problem}" + (f" (hint: {hint})" if hint else ""), file=sys.stderr)
        return 2

    try:
        drive = DriveConfig(law=ControlLaw(speed_limit_kmh=args.speed_limit, steer_limit_deg=args.steer_limit,
                                           tau=args.tau),
                            speed_unit=SpeedUnit(args.telemetry_speed_unit), smoothing=args.smoothing, gain=args.gain,
                            monitor=MonitorPolicy(mode=MonitorMode(args.monitor), slow_factor=args.monitor_slow))
        inference = InferenceConfig(threads=args.threads, provider=args.provider)
        fallback = FallbackPolicy(hold_frames=args.hold_frames)
        if args.workers < 1 or (args.workers > 1 and not hasattr(os, "fork")):
            raise BadValue(f"--workers must be >= 1 (and 1 where fork is unavailable), got {args.workers}")
        if args.record is not None and args.workers > 1:
            raise BadValue("--record works with one server process (--workers 1)")
        if args.ping_interval < 1:
            raise BadValue(f"--ping-interval must be >= 1 s, got {args.ping_interval}")
        if not 0 <= args.port <= 65535:
            raise BadValue(f"--port must be in 0..65535, got {args.port}")
        limits = WireLimits(max_connections=args.max_connections, header_timeout_s=args.header_timeout,
                            max_pending_replies=args.max_pending, idle_evict_s=args.idle_evict)
    except UserError as exc:  # a bare ValueError here is a bug, and keeps its traceback
        return fail(exc)
    model_path = args.model
    if model_path is None:
        model_path = default_model_path()
        if not model_path.is_file():
            return fail(f"no --model given and the bundled model {model_path} does not exist "
                        "(train one with `rbc train` or pass --model PATH)")
    try:
        model = SteeringModel(model_path, inference)
        model.warm_up()
        monitor_found = model.monitor() if drive.monitor.mode != MonitorMode.OFF else None
    except (ModelError, MonitorError) as exc:
        return fail(exc)

    # the port too is checked before anything is logged: a port in use is one line, like a bad model
    try:
        sock = listen.listening_socket(args.host, args.port)
    except listen.ListenError as exc:
        return fail(exc)

    # one frame at a time: OpenCV's worker threads only add wake-up latency to a 160x80 resize
    cv2.setNumThreads(1)
    # imported only now: the model check above must not pay for (or print anything from) eventlet
    from drive_server.serving.pipeline import DrivePipeline
    from drive_server.wire.server import DriveServer
    from drive_server.wire.transport import TransportTuning

    tuning = TransportTuning.stock() if args.stock_transport else TransportTuning()
    config = ServerConfig(host=args.host, port=args.port, log_every_s=args.log_every, stats_json=args.stats_json,
                          fallback=fallback, transport=tuning, ping_interval_s=args.ping_interval, limits=limits,
                          dashboard=_dashboard_wanted(args, sock))
    log.info("model %s", model.describe())
    smooth, whose = (model.smoothing, "the model's") if drive.smoothing is None else (drive.smoothing, "--smooth")
    gain, gain_whose = (model.gain, "the model's") if drive.gain is None else (drive.gain, "--gain")
    log.info("control: speed limit %.1f km/h, steer limit %.1f deg, tau %.2f, telemetry speed in %s, "
             "steering gain %g (%s)%s", drive.law.speed_limit_kmh, drive.law.steer_limit_deg, drive.law.tau,
             drive.speed_unit.value, gain, gain_whose,
             f", steering smoothed per client (alpha {smooth:g}, {whose})" if smooth < 1 else "")
    if monitor_found is not None:
        spec = monitor_found[0]
        log.info("monitor: %s (%s), warning at %.4g, alarm at %.4g, mean of %d frames%s", spec.score,
                 drive.monitor.mode.value, spec.warn, spec.alarm, spec.window,
                 f"; a warning slows to {drive.monitor.slow_factor:g}x the speed limit, an alarm stops the car"
                 if drive.monitor.mode == MonitorMode.ACT else "")
    elif drive.monitor.mode != MonitorMode.OFF:
        log.info("monitor: none (%s carries no misbehaviour monitor)", model_path.name)
    if not listen.is_local(sock.getsockname()[0]):
        log.warning(listen.EXPOSED_WARNING, listen.url(sock).removeprefix("http://"))
    if args.workers > 1:
        from drive_server.wire.workers import serve_workers

        def make_server(worker_config: ServerConfig) -> DriveServer:  # runs in each worker, after the fork
            return DriveServer(DrivePipeline(SteeringModel(model_path, inference), drive), worker_config)

        return serve_workers(args.workers, sock, model, config, make_server, tuning)
    try:
        server = DriveServer(DrivePipeline(model, drive), config)
    except UserError as exc:  # e.g. a patched library internal gone after an upgrade (drive_server.wire.patches)
        return fail(exc)
    server.adopt(sock)
    if args.record is not None:
        from drive_server.observing.recorder import Recorder

        server.recorder = Recorder(args.record)
    try:
        server.serve()
    finally:
        if server.recorder is not None:
            server.recorder.close()
    return 0

if __name__ == "__main__":
    raise SystemExit(main())
