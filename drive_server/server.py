"""The Socket.IO drive server: python-socketio 5 on eventlet, compatible with the Unity simulator.

Two kinds of client share one port: the Unity simulator, which never sends the Socket.IO CONNECT packet
``40`` (python-socketio 5 would drop all its events), and modern clients (python-socketio 5,
socket.io-client 4) that do. Every telemetry is answered exactly once, to its sender only, because the
simulator sends its next frame only after a reply. Each connected simulator has its own state.
"""

from __future__ import annotations

import json
import logging
import math
import signal
import warnings
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from time import monotonic, perf_counter
from typing import Any

from drive_server.guard import FallbackPolicy, FrameGuard
from drive_server.model import SteeringModel
from drive_server.pipeline import DrivePipeline, InferenceError
from drive_server.runrecords import write_json
from drive_server.stats import LatencyStats, save_stats, summarize, summary_line
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


def stats_document(model: SteeringModel, transport: TransportTuning, stats: list[LatencyStats],
                   workers: int = 1) -> dict[str, Any]:
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
        "clients": [dict(client=s.name, **s.summary()) for s in stats if s.name != RETIRED],
    }


class UnityCompatibleServer(socketio.Server):
    """A ``socketio.Server`` that joins a client to ``/`` on its first event if it never sent ``40``.

    The join is silent (no CONNECT reply is sent, since the simulator does not expect one) and runs the
    ``connect`` handler as a normal connection would. Clients that do send ``40`` are untouched.
    """

    def _handle_eio_message(self, eio_sid: str, data: Any) -> None:
        if (isinstance(data, str) and data[:1] == "2" and data[1:2] != "/"
                and eio_sid not in self._binary_packet
                and self.manager.sid_from_eio_sid(eio_sid, "/") is None):
            self._join_without_connect_packet(eio_sid)
        super()._handle_eio_message(eio_sid, data)

    def _join_without_connect_packet(self, eio_sid: str) -> None:
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


@dataclass
class ClientState:
    """What the server remembers about one connected simulator."""

    sid: str
    eio_sid: str | None
    user_agent: str
    stats: LatencyStats
    guard: FrameGuard
    last_warning: float = -math.inf
    unreported_malformed: int = 0


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
        self.clients: dict[str, ClientState] = {}
        self.finished: deque[LatencyStats] = deque()  # disconnected clients, newest last
        self.retired = LatencyStats(RETIRED, capacity=1)  # counters of clients dropped from ``finished``
        self._logged_upto: dict[str, int] = {}
        self._stop = False
        self._sock: Any = None
        self._logged_frames = -1
        self.recorder: Any = None  # a drive_server.recorder.Recorder with --record: gets every answered frame
        self.sio.on("connect", self._on_connect)
        self.sio.on("disconnect", self._on_disconnect)
        self.sio.on("telemetry", self._on_telemetry)
        self.app = socketio.WSGIApp(self.sio)

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
                self.retired.frames += old.frames
                self.retired.manual += old.manual
                self.retired.malformed += old.malformed
                self._logged_upto.pop(old.name, None)
            log.info("client %s disconnected (%s): %s", sid, reason, summary_line(client.stats.summary()))

    def _new_client(self, sid: str, agent: str) -> ClientState:
        eio_sid = self.sio.manager.eio_sid_from_sid(sid, "/") if self.transport.direct_reply else None
        return ClientState(sid, eio_sid, agent, LatencyStats(sid), FrameGuard(self.config.fallback))

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
        """
        if client.eio_sid is None:
            self.sio.emit(event, payload, to=client.sid)
        else:
            self.sio.eio.send(client.eio_sid, '2["' + event + '",' + json.dumps(payload, separators=(",", ":")) + "]")

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
            sent = client.guard.good(command)
            self._reply(client, "steer", encode_steer(sent))
            t5 = perf_counter()
        except (ProtocolError, InferenceError) as exc:
            self._fallback(client, str(exc))
            return
        except Exception as exc:  # never crash the connection, never leave the simulator waiting
            log.exception("unexpected error on a frame from %s", sid)
            self._fallback(client, f"internal error: {type(exc).__name__}")
            return
        client.stats.record((t_parse + decode, pre, infer, control + (t5 - t4), t5 - t0))
        if self.recorder is not None:  # after the reply: recording never delays the simulator
            self.recorder.record(telemetry.image_b64, sent, telemetry.speed)

    def _fallback(self, client: ClientState, reason: str) -> None:
        """Answer an unusable frame: hold the last good command for a few frames, then stop."""
        client.stats.malformed += 1
        command = client.guard.bad()
        self._reply(client, "steer", encode_steer(command))
        client.unreported_malformed += 1
        now = monotonic()
        if now - client.last_warning >= WARN_INTERVAL_S:
            action = "stopping" if command == self.config.fallback.stop_command else "holding the last command"
            log.warning("client %s: malformed frame (%s); %s [%d malformed since last warning, %d in total]",
                        client.sid, reason, action, client.unreported_malformed, client.stats.malformed)
            client.last_warning = now
            client.unreported_malformed = 0

    # -- statistics ------------------------------------------------------------------------------
    def all_stats(self) -> list[LatencyStats]:
        return [self.retired, *self.finished, *(c.stats for c in self.clients.values())]

    def stats_document(self) -> dict[str, Any]:
        return stats_document(self.pipeline.model, self.transport, self.all_stats())

    def write_stats(self) -> None:
        if self.config.stats_dump is not None:
            save_stats(self.config.stats_dump, self.all_stats())
        if self.config.stats_json is not None:
            write_json(self.config.stats_json, self.stats_document(), sort_keys=True)

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
        """Open the listening socket (raises ``OSError`` if the port is taken); returns (host, port)."""
        self._sock = eventlet.listen((self.config.host, self.config.port))
        return self._sock.getsockname()[:2]

    def adopt(self, sock: Any) -> None:
        """Serve on a listening socket opened by someone else (a worker process's parent)."""
        self._sock = eventlet.greenio.GreenSocket(sock)

    def serve(self, announce: bool = True) -> None:
        """Listen until SIGINT/SIGTERM or ``stop()``; writes the stats JSON on the way out."""
        if self._sock is None:
            self.bind()
        sock = self._sock
        host, port = sock.getsockname()[:2]
        server = eventlet.spawn(eventlet.wsgi.server, sock, self.app, log_output=False, debug=False,
                                log=logging.getLogger("eventlet.wsgi"))
        if self.config.log_every_s > 0:
            self.sio.start_background_task(self._log_loop)
        previous = {s: signal.signal(s, self.stop) for s in (signal.SIGINT, signal.SIGTERM)}
        if announce:
            log.info("listening on http://%s:%d", host, port)
        try:
            while not self._stop and not server.dead:
                eventlet.sleep(0.2)  # a signal only sets a flag; this loop notices it
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
            server.kill()
            total = summarize(self.all_stats())
            log.info("stopped: %s", summary_line(total))
            self.write_stats()
