"""python-socketio's server, made to accept the Unity simulator, which never sends the CONNECT packet ``40``.

Also the first check of every packet: what no Socket.IO client sends is refused before python-socketio
parses it (see :mod:`drive_server.wire.limits`), and a telemetry too broken to decode is still answered.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import socketio

from drive_server.wire.limits import TELEMETRY_EVENT, json_problem
from drive_server.wire.patches import eventlet_engineio as wire

log = logging.getLogger(__name__)


class UnityCompatibleServer(socketio.Server):  # type: ignore[misc]  # python-socketio has no stubs: Any
    """A ``socketio.Server`` that joins a client to ``/`` on its first event if it never sent ``40``.

    The join is silent (no CONNECT reply is sent, since the simulator does not expect one) and runs the
    ``connect`` handler as a normal connection would. Clients that do send ``40`` are untouched.
    """

    #: Set by ``DriveServer``: answer a telemetry that cannot be decoded (sid, kind, reason), and close a
    #: connection after a protocol error (eio_sid, reason).
    on_bad_telemetry: Callable[[str, str, str], None]
    on_protocol_error: Callable[[str, str], None]
    manager_initialized: bool  # socketio.Server's own (the package is untyped)

    def __init__(self, *args: object, **kwargs: object) -> None:  # socketio.Server's arguments
        super().__init__(*args, **kwargs)
        self.stock_message = wire.intercept_engine_messages(self, self.handle_message)

    def handle_message(self, eio_sid: str, data: str | bytes) -> None:
        """Every engine.io message, before python-socketio's own handling (``stock_message``)."""
        session = self.eio.sockets.get(eio_sid)
        if session is None or session.closed or session.closing:
            return  # closed by the server: frames still in flight are dropped, never rejoined
        if not isinstance(data, str) or data[:1] not in ("0", "1", "2", "3"):
            # the transports refuse these already (drive_server.wire.limits); kept so no path can reach
            # python-socketio's binary-attachment state, which once swallowed every later frame
            self.on_protocol_error(eio_sid, "not a Socket.IO packet of type 0-3")
            return
        telemetry = TELEMETRY_EVENT.match(data) is not None
        problem = json_problem(data)
        if problem is None:
            if data[:1] == "2" and data[1:2] != "/" and self.manager.sid_from_eio_sid(eio_sid, "/") is None:
                self._join_without_connect_packet(eio_sid)
            try:
                self.stock_message(eio_sid, data)
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
        sid: str = self.manager.connect(eio_sid, "/")
        log.info("client %s sent an event without a CONNECT packet (the Unity simulator does that): "
                 "joined it to '/'", sid)
        try:
            wire.run_connect_handler(self, sid, self.environ.get(eio_sid, {}))
        except Exception:
            log.exception("connect handler failed for %s", sid)
        return sid
