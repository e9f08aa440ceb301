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
from dataclasses import replace
from time import perf_counter
from typing import TYPE_CHECKING

from drive_server.observing.stats import LatencyStats, summary_line
from drive_server.serving.guard import FrameGuard
from drive_server.serving.pipeline import DrivePipeline, InferenceError
from drive_server.wire import listen, patches
from drive_server.wire.connections import ConnectionLimiter, protocol_class, shutdown_socket
from drive_server.wire.gates import limited_websocket_class, polling_gate
from drive_server.wire.limits import CLOSE_PROTOCOL_ERROR, FaultLog, close_reason
from drive_server.wire.patches import eventlet_engineio as wire
from drive_server.wire.transport import install
from protocol import ProtocolError, encode_steer, parse_telemetry

if TYPE_CHECKING:
    import socket
    from wsgiref.types import WSGIEnvironment

    from drive_server.observing.recorder import Recorder

warnings.filterwarnings("ignore", message=r"\s*Eventlet is deprecated")  # printed on import; says nothing to users
import eventlet  # noqa: E402
import eventlet.greenio  # noqa: E402
import eventlet.wsgi  # noqa: E402
import socketio  # noqa: E402

from drive_server.observing import live  # noqa: E402
from drive_server.observing.dashboard import LiveFrame  # noqa: E402
from drive_server.wire.clients import ClientState  # noqa: E402
from drive_server.wire.server_config import ServerConfig  # noqa: E402
from drive_server.wire.server_stats import ServerStats  # noqa: E402
from drive_server.wire.unity_compat import UnityCompatibleServer  # noqa: E402

log = logging.getLogger(__name__)

#: At most one malformed-frame warning per client in this many seconds.
WARN_INTERVAL_S = 5.0
SESSION_LOG_INTERVAL_S, SESSION_LOG_BURST = 10.0, 20  # connect/disconnect lines: 20 of each per 10 s
#: Connection slots beyond ``max_connections`` in eventlet's pool, so refusals are answered at once
#: instead of waiting in the accept queue behind a full pool.
SPARE_SLOTS = 64
#: engine.io's async backend; its patches of library internals are ``drive_server.wire.patches.BACKENDS[ASYNC_MODE]``.
ASYNC_MODE = "eventlet"
#: Bad-input kind of a ``ProtocolError`` by the field it names (``exc.field``; the wording of its message is for
#: people and may change); any other field is a bad ``payload``.
_INPUT_KINDS = {"image": "image", "speed": "number", "steering_angle": "number", "throttle": "number"}


class DriveServer:
    """Wires the drive pipeline to Socket.IO events: ``telemetry`` in, ``steer``/``manual`` out."""

    def __init__(self, pipeline: DrivePipeline, config: ServerConfig | None = None) -> None:
        patches.check(ASYNC_MODE)  # one warning line for an unchecked library version; refused if a name is gone
        self.pipeline = pipeline
        self.config = config = config or ServerConfig()
        self.sio = UnityCompatibleServer(
            async_mode=ASYNC_MODE, logger=False, engineio_logger=False,
            async_handlers=False,  # run each event in its reader greenthread: no greenthread spawn per frame
            max_http_buffer_size=config.limits.max_message_bytes, ping_interval=config.ping_interval_s,
            transports=list(config.transports),
        )
        self.transport = install(self.sio.eio, config.transport)
        self.limits = config.limits
        self.clients: dict[str, ClientState] = {}
        self.stats = ServerStats(config, pipeline, self.transport, self.clients)
        self.fault_log = FaultLog(self.stats.faults, WARN_INTERVAL_S)
        # a client can reconnect in a loop: its connect/disconnect lines are bounded like its faults
        self.session_log = FaultLog(None, SESSION_LOG_INTERVAL_S, logging.INFO, SESSION_LOG_BURST, log)
        eio = self.sio.eio
        self.limiter = ConnectionLimiter(self.limits, self.fault_log)  # the cap, shared with the upgraded sockets
        wire.wrap_websocket_class(eio, lambda base: limited_websocket_class(base, self.limiter))
        self.sio.on_bad_telemetry = self._on_bad_telemetry
        self.sio.on_protocol_error = self._on_protocol_error
        self._stop = False
        self._sock: eventlet.greenio.GreenSocket | None = None  # eventlet has no stubs: Any to mypy
        self.recorder: Recorder | None = None  # with --record: gets every answered frame
        self.sio.on("connect", self._on_connect)
        self.sio.on("disconnect", self._on_disconnect)
        self.sio.on("telemetry", self._on_telemetry)
        self.dashboard = live.make_dashboard(self) if config.dashboard else None
        pages = self.dashboard.wsgi if self.dashboard is not None else None  # every path but /socket.io/
        self.app = polling_gate(socketio.WSGIApp(self.sio, wsgi_app=pages), eio, self.limits, self.fault_log)

    # -- events ----------------------------------------------------------------------------------
    def _on_connect(self, sid: str, environ: WSGIEnvironment, auth: object = None) -> None:
        agent = environ.get("HTTP_USER_AGENT", "?")
        peer = f"{environ.get('REMOTE_ADDR', '?')}:{environ.get('REMOTE_PORT', '?')}"
        self.clients[sid] = self._new_client(sid, agent)
        self.session_log.report("connect", "client %s connected from %s (%s); %d connected", sid, peer, agent,
                                len(self.clients))

    def _on_disconnect(self, sid: str, reason: object = None) -> None:
        client = self.clients.pop(sid, None)
        if client is not None:
            self.stats.client_left(client.stats)
            self.session_log.report("disconnect", "client %s disconnected (%s): %s", sid, reason,
                                    summary_line(client.stats.summary()))

    def _new_client(self, sid: str, agent: str) -> ClientState:
        eio_sid = self.sio.manager.eio_sid_from_sid(sid, "/")
        ws = self.sio.environ.get(eio_sid, {}).get("rbc.websocket") if eio_sid else None
        return ClientState(sid, eio_sid, self.transport.direct_reply and eio_sid is not None, agent,
                           LatencyStats(sid), FrameGuard(self.config.fallback), socket=getattr(ws, "socket", None),
                           smoother=self.pipeline.smoother(), monitor=self.pipeline.client_monitor(sid))

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
        if session is not None and client.not_reading(session, self.limits.max_pending_replies):
            self.fault_log.report("slow_reader", "client %s does not read its replies (%d queued, %d bytes unsent, "
                                  "--max-pending %d): disconnected", client.sid, session.queue.qsize(),
                                  client.unsent, self.limits.max_pending_replies)
            self._close(session.sid, "", hard=True)  # the engine.io session's id: client.eio_sid
            return
        if not client.direct:
            self.sio.emit(event, payload, to=client.sid)
        else:
            self.sio.eio.send(client.eio_sid, '2["' + event + '",' + json.dumps(payload, separators=(",", ":")) + "]")

    def _on_telemetry(self, sid: str, payload: object = None, *_: object) -> None:
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
            command, (decode, pre, infer, control) = self.pipeline.run(telemetry, client.smoother, client.monitor)
            t4 = perf_counter()
            sent = client.guard.good(command)
            self._reply(client, "steer", encode_steer(sent))
            t5 = perf_counter()
        except ProtocolError as exc:
            self._fallback(client, _INPUT_KINDS.get(exc.field, "payload"), str(exc))
            return
        except InferenceError as exc:
            self._fallback(client, "model_output", str(exc))
            return
        except Exception as exc:  # never crash the connection, never leave the simulator waiting
            log.debug("unexpected error on a frame from %s", sid, exc_info=True)  # the traceback only with -v
            self._fallback(client, "internal", f"internal error: {type(exc).__name__}: {exc}"[:200])
            return
        client.stats.record((t_parse + decode, pre, infer, control + (t5 - t4), t5 - t0))
        if client.monitor is not None:
            client.stats.monitor.note(client.monitor)
        if self.recorder is not None:  # after the reply: recording never delays the simulator
            self.recorder.record(telemetry.image_b64, sent, telemetry.speed,
                                 client.monitor.last if client.monitor is not None else None)
        if self.dashboard is not None:  # one assignment: the live view reads it off the hot path
            client.live = LiveFrame(t0, telemetry.image_b64, sent.steering, sent.throttle, telemetry.speed, False,
                                    client.monitor.last if client.monitor is not None else None)

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
                wire.send_close_frame(ws, CLOSE_PROTOCOL_ERROR, close_reason(reason))
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
        if client.live is not None:  # the live view shows the fallback command over the last good frame
            client.live = replace(client.live, t=perf_counter(), steering=command.steering,
                                  throttle=command.throttle, fallback=True)
        action = "stopping" if command == self.config.fallback.stop_command else "holding the last command"
        what = "model output" if kind == "model_output" else "malformed frame"
        self.fault_log.report(f"frame:{kind}", "client %s: %s (%s); %s [%d malformed, %d non-finite outputs "
                              "from this client]", client.sid, what, reason, action, client.stats.malformed,
                              client.stats.bad_output, count=False)

    # -- statistics ------------------------------------------------------------------------------
    def _log_loop(self) -> None:
        """Every ``log_every_s``: counters since start, percentiles of the frames since the last line."""
        while not self._stop:
            self.sio.sleep(self.config.log_every_s)
            line = self.stats.progress_line()
            if line is not None:
                log.info("%s", line)

    # -- running ---------------------------------------------------------------------------------
    def stop(self, *_: object) -> None:
        """Ask ``serve`` to return (safe from a signal handler)."""
        self._stop = True

    def bind(self) -> tuple[str, int]:
        """Open the listening socket (raises ``ListenError`` with a one-line message if the port is taken,
        out of range or the address unusable); returns (host, port)."""
        self._sock = eventlet.greenio.GreenSocket(listen.listening_socket(self.config.host, self.config.port))
        address: tuple[str, int] = self._sock.getsockname()[:2]
        return address

    def adopt(self, sock: socket.socket) -> None:
        """Serve on a listening socket opened by someone else (a worker process's parent)."""
        self._sock = eventlet.greenio.GreenSocket(sock)

    def serve(self, announce: bool = True) -> None:
        """Listen until SIGINT/SIGTERM or ``stop()``; writes the stats JSON on the way out."""
        if self._sock is None:
            self.bind()
        sock = self._sock
        assert sock is not None  # bound above
        limiter = self.limiter
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
            if self.dashboard is not None:
                log.info("live view (read-only) at %s/", listen.url(sock))
        collected_upto = 0
        try:
            while not self._stop and not server.dead:
                eventlet.sleep(0.2)  # a signal only sets a flag; this loop notices it
                if limiter.ended != collected_upto and not self.clients:
                    # A connection that ended on an error (a live-view viewer gone: EPIPE) leaves its socket
                    # in a reference cycle through the traceback, and only the collector closes its fd. With
                    # simulators connected, their traffic runs the collector; a quiet server would keep such
                    # fds until the next telemetry (rbc soak saw one per viewer). Cheap: gc.freeze() above.
                    collected_upto = limiter.ended
                    gc.collect()
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
            server.kill()
            log.info("stopped: %s", self.stats.final_line())
            self.stats.write()
