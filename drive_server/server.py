"""The Socket.IO drive server: python-socketio 5 on eventlet, compatible with the Unity simulator.

Two kinds of client share one port: the Unity simulator, which never sends the Socket.IO CONNECT packet
``40`` (python-socketio 5 would drop all its events), and modern clients (python-socketio 5,
socket.io-client 4) that do. Every telemetry is answered exactly once, to its sender only, because the
simulator sends its next frame only after a reply. Each connected simulator has its own state.
"""

from __future__ import annotations

import gc
import json
import logging
import signal
import warnings
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from time import perf_counter
from typing import Any

from drive_server import listen
from drive_server.guard import FallbackPolicy, FrameGuard
from drive_server.limits import (
    CLOSE_PROTOCOL_ERROR,
    MAX_UNSENT_BYTES,
    TELEMETRY_EVENT,
    ConnectionLimiter,
    FaultLog,
    WireLimits,
    close_reason,
    json_problem,
    limited_websocket_class,
    polling_gate,
    protocol_class,
    shutdown_socket,
    unsent_bytes,
)
from drive_server.model import SteeringModel
from drive_server.pipeline import DrivePipeline, InferenceError
from drive_server.stats import FaultCounters, LatencyStats, save_stats, summarize, summary_line, write_json_atomic
from drive_server.transport import TransportTuning, install
from protocol import ProtocolError, encode_steer, parse_telemetry

warnings.filterwarnings("ignore", message=r"\s*Eventlet is deprecated")  # printed on import; says nothing to users
import eventlet  # noqa: E402
import eventlet.greenio  # noqa: E402
import eventlet.wsgi  # noqa: E402
import socketio  # noqa: E402

log = logging.getLogger(__name__)

#: Largest accepted Socket.IO message. A 320x160 JPEG is ~16 KB (21 KB in base64) at the simulator's
#: quality 75; even pure noise at quality 100 is 102 KB (136 KB in base64). 256 KiB leaves margin for
#: any real frame and refuses anything else before it is buffered.
MAX_MESSAGE_BYTES = 256 * 1024
#: At most one malformed-frame warning per client in this many seconds.
WARN_INTERVAL_S = 5.0
#: Disconnected clients whose statistics are kept individually (older ones only add to the counters).
MAX_FINISHED_CLIENTS = 64
RETIRED = "retired"
#: Connection slots beyond ``max_connections`` in eventlet's pool, so refusals are answered at once
#: instead of waiting in the accept queue behind a full pool.
SPARE_SLOTS = 64
#: Bad-input kind of a ``ProtocolError`` by the field its message starts with.
_INPUT_KINDS = {"image": "image", "speed": "number", "steering_angle": "number", "throttle": "number"}


@dataclass(frozen=True)
class ServerConfig:
    """Socket and bookkeeping settings (the control law lives in ``DriveConfig``)."""

    host: str = "127.0.0.1"
    port: int = 4567
    log_every_s: float = 10.0  # period of the one-line latency summary; 0 disables it
    stats_json: Path | None = None
    fallback: FallbackPolicy = field(default_factory=FallbackPolicy)
    transport: TransportTuning = field(default_factory=TransportTuning)
    max_message_bytes: int = MAX_MESSAGE_BYTES
    ping_interval_s: float = 25.0  # Engine.IO heartbeat (the simulator pings every 25 s as well)
    transports: tuple[str, ...] = ("polling", "websocket")  # worker processes accept websocket only
    stats_dump: Path | None = None  # raw statistics for the parent of a worker process
    max_connections: int = 256  # open TCP connections (a simulator holds one)
    header_timeout_s: float = 10.0  # to send the request line and headers (and a long-polling body)
    max_pending_replies: int = 64  # replies queued for a client that does not read them: then it is dropped

    @property
    def limits(self) -> WireLimits:
        return WireLimits(max_message_bytes=self.max_message_bytes, max_connections=self.max_connections,
                          header_timeout_s=self.header_timeout_s, max_pending_replies=self.max_pending_replies)


def stats_document(model: SteeringModel, transport: TransportTuning, stats: list[LatencyStats],
                   workers: int = 1, faults: dict[str, int] | None = None,
                   limits: WireLimits | None = None) -> dict[str, Any]:
    """What ``--stats-json`` holds: the model, the settings, totals and one entry per client."""
    return {
        "model": str(model.path),
        "contract_source": model.contract_source,
        "contract": model.contract.__dict__,
        "threads": model.config.threads,
        "provider": model.config.provider,
        "workers": workers,
        "transport": transport.__dict__,
        "total": summarize(stats),
        "faults": faults or {},
        "limits": (limits or WireLimits()).__dict__,
        "clients": [dict(client=s.name, **s.summary()) for s in stats if s.name != RETIRED],
    }


class UnityCompatibleServer(socketio.Server):
    """A ``socketio.Server`` that joins a client to ``/`` on its first event if it never sent ``40``.

    The join is silent (no CONNECT reply is sent, since the simulator does not expect one) and runs the
    ``connect`` handler as a normal connection would. Clients that do send ``40`` are untouched.
    """

    #: Set by ``DriveServer``: answer a telemetry that cannot be decoded (sid, kind, reason), and close a
    #: connection after a protocol error (eio_sid, reason).
    on_bad_telemetry: Any = None
    on_protocol_error: Any = None

    def _handle_eio_message(self, eio_sid: str, data: Any) -> None:
        session = self.eio.sockets.get(eio_sid)
        if session is None or session.closed or session.closing:
            return  # closed by the server: frames still in flight are dropped, never rejoined
        if not isinstance(data, str) or data[:1] not in ("0", "1", "2", "3"):
            # the transports refuse these already (drive_server.limits); kept so no path can reach
            # python-socketio's binary-attachment state, which once swallowed every later frame
            self.on_protocol_error(eio_sid, "not a Socket.IO packet of type 0-3")
            return
        telemetry = TELEMETRY_EVENT.match(data) is not None
        problem = json_problem(data)
        if problem is None:
            if data[:1] == "2" and data[1:2] != "/" and self.manager.sid_from_eio_sid(eio_sid, "/") is None:
                self._join_without_connect_packet(eio_sid)
            try:
                super()._handle_eio_message(eio_sid, data)
                return
            except ValueError as exc:  # python-socketio's packet decoder: invalid JSON, bad ids, ...
                problem = f"invalid Socket.IO packet ({str(exc).splitlines()[0][:80]})"
        if telemetry:  # a telemetry the simulator could have sent: answered, however broken
            sid = self.manager.sid_from_eio_sid(eio_sid, "/")
            if sid is None:
                sid = self._join_without_connect_packet(eio_sid)
            self.on_bad_telemetry(sid, "json", problem)
        else:
            self.on_protocol_error(eio_sid, problem)

    def _join_without_connect_packet(self, eio_sid: str) -> str:
        if not self.manager_initialized:
            self.manager_initialized = True
            self.manager.initialize()
        sid = self.manager.connect(eio_sid, "/")
        log.info("client %s sent an event without a CONNECT packet (the Unity simulator does that): "
                 "joined it to '/'", sid)
        try:
            self._trigger_event("connect", "/", sid, self.environ.get(eio_sid, {}), None)
        except Exception:
            log.exception("connect handler failed for %s", sid)
        return sid


@dataclass
class ClientState:
    """What the server remembers about one connected simulator."""

    sid: str
    eio_sid: str | None
    direct: bool  # replies handed to engine.io directly (``TransportTuning.direct_reply``)
    user_agent: str
    stats: LatencyStats
    guard: FrameGuard
    socket: Any = None  # the WebSocket's TCP socket (None for long-polling)
    replies: int = 0
    unsent: int = 0


class DriveServer:
    """Wires the drive pipeline to Socket.IO events: ``telemetry`` in, ``steer``/``manual`` out."""

    def __init__(self, pipeline: DrivePipeline, config: ServerConfig = ServerConfig()) -> None:
        self.pipeline = pipeline
        self.config = config
        self.sio = UnityCompatibleServer(
            async_mode="eventlet", logger=False, engineio_logger=False,
            async_handlers=False,  # run each event in its reader greenthread: no greenthread spawn per frame
            max_http_buffer_size=config.max_message_bytes, ping_interval=config.ping_interval_s,
            transports=list(config.transports),
        )
        self.transport = install(self.sio.eio, config.transport)
        self.limits = config.limits
        self.faults = FaultCounters()
        self.fault_log = FaultLog(self.faults, WARN_INTERVAL_S)
        eio = self.sio.eio
        eio._async = dict(eio._async)  # our own copy of the driver table (the module-level one stays stock)
        eio._async["websocket"] = limited_websocket_class(eio._async["websocket"], self.limits, self.fault_log)
        self.sio.on_bad_telemetry = self._on_bad_telemetry
        self.sio.on_protocol_error = self._on_protocol_error
        self.clients: dict[str, ClientState] = {}
        self.finished: deque[LatencyStats] = deque()  # disconnected clients, newest last
        self.retired = LatencyStats(RETIRED, capacity=1)  # counters of clients dropped from ``finished``
        self._logged_upto: dict[str, int] = {}
        self._stop = False
        self._sock: Any = None
        self._logged_frames = -1
        self.sio.on("connect", self._on_connect)
        self.sio.on("disconnect", self._on_disconnect)
        self.sio.on("telemetry", self._on_telemetry)
        self.app = polling_gate(socketio.WSGIApp(self.sio), eio, self.limits, self.fault_log)

    # -- events ----------------------------------------------------------------------------------
    def _on_connect(self, sid: str, environ: dict[str, Any], auth: Any = None) -> None:
        agent = environ.get("HTTP_USER_AGENT", "?")
        peer = f"{environ.get('REMOTE_ADDR', '?')}:{environ.get('REMOTE_PORT', '?')}"
        self.clients[sid] = self._new_client(sid, agent)
        log.info("client %s connected from %s (%s); %d connected", sid, peer, agent, len(self.clients))

    def _on_disconnect(self, sid: str, reason: Any = None) -> None:
        client = self.clients.pop(sid, None)
        if client is not None:
            self.finished.append(client.stats)
            while len(self.finished) > MAX_FINISHED_CLIENTS:  # bound memory over many reconnections
                old = self.finished.popleft()
                self.retired.absorb_counters(old)
                self._logged_upto.pop(old.name, None)
            log.info("client %s disconnected (%s): %s", sid, reason, summary_line(client.stats.summary()))

    def _new_client(self, sid: str, agent: str) -> ClientState:
        eio_sid = self.sio.manager.eio_sid_from_sid(sid, "/")
        ws = self.sio.environ.get(eio_sid, {}).get("rbc.websocket") if eio_sid else None
        return ClientState(sid, eio_sid, self.transport.direct_reply and eio_sid is not None, agent,
                           LatencyStats(sid), FrameGuard(self.config.fallback), socket=getattr(ws, "socket", None))

    def _client(self, sid: str) -> ClientState:
        client = self.clients.get(sid)
        if client is None:  # an event raced its connect handler; never leave a frame unanswered
            client = self.clients[sid] = self._new_client(sid, "?")
        return client

    def _reply(self, client: ClientState, event: str, payload: dict[str, str]) -> None:
        """Send ``event`` to this client only.

        With ``direct_reply`` the Socket.IO EVENT packet (``2["event",{...}]`` on ``/``) is encoded here
        and handed to engine.io's public ``send``: the same bytes ``socketio.emit(..., to=sid)``
        produces, without its room lookup, binary scan and generic packet encoder on every frame.

        A client with ``max_pending_replies`` replies still queued does not read them (a simulator has
        two frames in flight): it is disconnected instead of being served, and its queue grown, forever.
        """
        session = self.sio.eio.sockets.get(client.eio_sid) if client.eio_sid else None
        if session is not None and self._not_reading(client, session):
            self.fault_log.report("slow_reader", "client %s does not read its replies (%d queued, %d bytes unsent, "
                                  "--max-pending %d): disconnected", client.sid, session.queue.qsize(),
                                  client.unsent, self.limits.max_pending_replies)
            self._close(client.eio_sid, "", hard=True)
            return
        if not client.direct:
            self.sio.emit(event, payload, to=client.sid)
        else:
            self.sio.eio.send(client.eio_sid, '2["' + event + '",' + json.dumps(payload, separators=(",", ":")) + "]")

    def _not_reading(self, client: ClientState, session: Any) -> bool:
        """Replies pile up in engine.io's queue, or (checked every 32 replies: one ioctl) in the kernel."""
        if session.queue.qsize() >= self.limits.max_pending_replies:
            return True
        client.replies += 1
        if client.replies % 32 or client.socket is None:
            return False
        client.unsent = unsent_bytes(client.socket)
        return client.unsent > MAX_UNSENT_BYTES

    def _on_telemetry(self, sid: str, payload: Any = None, *_: Any) -> None:
        # no payload at all is manual mode too: python-socketio's ``emit("telemetry", None)`` sends that
        t0 = perf_counter()
        client = self._client(sid)
        try:
            telemetry = parse_telemetry(payload)
            if telemetry is None:  # a key is held in the simulator: manual mode
                client.stats.manual += 1
                self._reply(client, "manual", {})
                return
            t_parse = perf_counter() - t0
            command, (decode, pre, infer, control) = self.pipeline.run(telemetry)
            t4 = perf_counter()
            self._reply(client, "steer", encode_steer(client.guard.good(command)))
            t5 = perf_counter()
        except ProtocolError as exc:
            self._fallback(client, _INPUT_KINDS.get(str(exc).split(":", 1)[0], "payload"), str(exc))
            return
        except InferenceError as exc:
            self._fallback(client, "model_output", str(exc))
            return
        except Exception as exc:  # never crash the connection, never leave the simulator waiting
            log.debug("unexpected error on a frame from %s", sid, exc_info=True)  # the traceback only with -v
            self._fallback(client, "internal", f"internal error: {type(exc).__name__}: {exc}"[:200])
            return
        client.stats.record((t_parse + decode, pre, infer, control + (t5 - t4), t5 - t0))

    def _on_bad_telemetry(self, sid: str, kind: str, reason: str) -> None:
        """A telemetry event too broken to decode (JSON too deep, a huge number): answered all the same."""
        self._fallback(self._client(sid), kind, reason)

    def _on_protocol_error(self, eio_sid: str, reason: str) -> None:
        self.fault_log.report("protocol_error", "connection %s: protocol error (%s): closed", eio_sid, reason)
        self._close(eio_sid, reason)

    def _close(self, eio_sid: str, reason: str, hard: bool = False) -> None:
        """Close one connection now: a WebSocket close frame 1002 (``hard``: a TCP reset, for a client whose
        unread replies block any further send), then end the session without waiting."""
        ws = self.sio.environ.get(eio_sid, {}).get("rbc.websocket")
        if ws is not None:
            if hard:
                shutdown_socket(ws.socket, reset=True)
            else:
                ws._send_closing_frame(True, close_data=(CLOSE_PROTOCOL_ERROR, close_reason(reason)))
        session = self.sio.eio.sockets.get(eio_sid)
        if session is not None and not session.closed:
            session.close(wait=False, abort=ws is not None)  # wait=True could wait forever for a poll

    def _fallback(self, client: ClientState, kind: str, reason: str) -> None:
        """Answer an unusable frame: hold the last good command for a few frames, then stop.

        ``kind`` says what was unusable: a kind of bad input (counted as malformed), or ``model_output``
        (a non-finite steering value: the model's fault, counted on its own). Logged through the
        rate-limited fault log: one line per kind per interval, whatever the number of clients.
        """
        if kind == "model_output":
            client.stats.bad_output += 1
        else:
            client.stats.count_bad_input(kind)
        command = client.guard.bad()
        self._reply(client, "steer", encode_steer(command))
        action = "stopping" if command == self.config.fallback.stop_command else "holding the last command"
        what = "model output" if kind == "model_output" else "malformed frame"
        self.fault_log.report(f"frame:{kind}", "client %s: %s (%s); %s [%d malformed, %d non-finite outputs "
                              "from this client]", client.sid, what, reason, action, client.stats.malformed,
                              client.stats.bad_output, count=False)

    # -- statistics ------------------------------------------------------------------------------
    def all_stats(self) -> list[LatencyStats]:
        return [self.retired, *self.finished, *(c.stats for c in self.clients.values())]

    def stats_document(self) -> dict[str, Any]:
        return stats_document(self.pipeline.model, self.transport, self.all_stats(), faults=self.faults.as_dict(),
                              limits=self.limits)

    def write_stats(self) -> None:
        if self.config.stats_dump is not None:
            save_stats(self.config.stats_dump, self.all_stats())
            write_json_atomic(self.config.stats_dump.with_suffix(".faults.json"), self.faults.as_dict())
        if self.config.stats_json is not None:
            write_json_atomic(self.config.stats_json, self.stats_document())

    def _log_loop(self) -> None:
        """Every ``log_every_s``: counters since start, percentiles of the frames since the last line."""
        while not self._stop:
            self.sio.sleep(self.config.log_every_s)
            stats = self.all_stats()
            frames = sum(s.frames + s.malformed + s.manual for s in stats)
            if frames != self._logged_frames:
                self._logged_frames = frames
                line = summary_line(summarize(stats, since=self._logged_upto))
                self._logged_upto = {s.name: s.recorded for s in stats}
                log.info("%d client(s): %s", len(self.clients), line)

    # -- running ---------------------------------------------------------------------------------
    def stop(self, *_: Any) -> None:
        """Ask ``serve`` to return (safe from a signal handler)."""
        self._stop = True

    def bind(self) -> tuple[str, int]:
        """Open the listening socket (raises ``ListenError`` with a one-line message if the port is taken,
        out of range or the address unusable); returns (host, port)."""
        self._sock = eventlet.greenio.GreenSocket(listen.listening_socket(self.config.host, self.config.port))
        return self._sock.getsockname()[:2]

    def adopt(self, sock: Any) -> None:
        """Serve on a listening socket opened by someone else (a worker process's parent)."""
        self._sock = eventlet.greenio.GreenSocket(sock)

    def serve(self, announce: bool = True) -> None:
        """Listen until SIGINT/SIGTERM or ``stop()``; writes the stats JSON on the way out."""
        if self._sock is None:
            self.bind()
        sock = self._sock
        limiter = ConnectionLimiter(self.limits, self.fault_log)
        server = eventlet.spawn(eventlet.wsgi.server, sock, self.app, log_output=False, debug=False,
                                log=logging.getLogger("eventlet.wsgi"), protocol=protocol_class(limiter),
                                max_size=self.limits.max_connections + SPARE_SLOTS)
        if self.config.log_every_s > 0:
            self.sio.start_background_task(self._log_loop)
        previous = {s: signal.signal(s, self.stop) for s in (signal.SIGINT, signal.SIGTERM)}
        # everything loaded so far (modules, ONNX Runtime, eventlet) lives as long as the server: moved out of
        # the collector's reach, a full collection no longer walks it between two frames (a multi-ms pause)
        gc.freeze()
        if announce:
            log.info("listening on %s", listen.url(sock))
        try:
            while not self._stop and not server.dead:
                eventlet.sleep(0.2)  # a signal only sets a flag; this loop notices it
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
            server.kill()
            total = summarize(self.all_stats())
            faults = ", ".join(f"{kind} {n}" for kind, n in self.faults.as_dict().items())
            log.info("stopped: %s%s", summary_line(total), f" | refused/closed: {faults}" if faults else "")
            self.write_stats()
