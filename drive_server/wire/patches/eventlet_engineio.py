"""The eventlet backend's patches of eventlet, python-engineio and python-socketio internals, each a named function.

The libraries are imported inside the functions: the command line imports this module (through
:mod:`drive_server.wire.transport`) and must not pay for, or print anything from, eventlet before it serves.
On an upgrade: read each function below against the new library, update ``CHECKED_VERSIONS`` and run
``tests/test_wire_patches.py`` and the wire tests it names.
The three libraries ship no type information: the parts of their objects the server uses are the protocols below
(:class:`EventletWebSocket`, :class:`EngineServer`, :class:`EngineSession`, :class:`SocketServer`).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Protocol, cast

from drive_server.wire.patches import PrivateName

if TYPE_CHECKING:
    from wsgiref.types import StartResponse, WSGIEnvironment

    from drive_server.wire.patches import TcpSocket

#: engine.io's ``message`` handler: (eio_sid, the message: text, or bytes for a binary one).
MessageHandler = Callable[[str, str | bytes], None]


class EventletWebSocket(Protocol):
    """What the server uses of eventlet's ``RFC6455WebSocket`` (one upgraded connection): the message class its
    frame parser builds (bounded per connection), its TCP socket, ``wait`` for the next message (replaced per
    connection), and the two private names patched below."""

    Message: type
    socket: TcpSocket
    wait: Callable[[], str | bytes | None]
    _apply_mask: Callable[..., bytes]

    def _send_closing_frame(self, ignore_send_errors: bool = False,
                            close_data: tuple[int, str] | None = None) -> None: ...


class _Queue(Protocol):
    def qsize(self) -> int: ...


class EngineSession(Protocol):
    """What the server uses of python-engineio's ``Socket`` (one client's session)."""

    closed: bool
    closing: bool
    queue: _Queue  # the packets waiting to be sent to the client

    def close(self, wait: bool = True, abort: bool = False) -> None: ...


class EngineServer(Protocol):
    """What the server uses of python-engineio's ``Server``: its mode, its sessions by id, its message handler's
    registration, and its async driver's table (private, :func:`wrap_websocket_class`)."""

    async_mode: str
    sockets: dict[str, EngineSession]
    _async: dict[str, object]

    def on(self, event: str, handler: MessageHandler) -> object: ...


class SocketServer(Protocol):
    """What the patches use of python-socketio's ``Server``: its engine.io server and two private methods."""

    eio: EngineServer
    _handle_eio_message: MessageHandler

    def _trigger_event(self, event: str, namespace: str, *args: object) -> object: ...

#: The versions every patch below was read against and tested with (the wire tests, the hostile campaign).
CHECKED_VERSIONS: dict[str, tuple[str, ...]] = {
    "eventlet": ("0.41.3",),
    "python-engineio": ("4.15.1",),
    "python-socketio": ("5.18.1",),
}

#: eventlet minor versions (inclusive) whose frame parser calls ``_apply_mask`` as the fast unmask expects:
#: the project's floor up to the newest read. Outside it the unmask stays stock (a slower server, no error).
FAST_UNMASK_EVENTLET = ((0, 35), (0, 41))

#: Every private name used below, with the function that uses it (``check`` verifies each at start-up).
PRIVATE_NAMES: tuple[PrivateName, ...] = (
    PrivateName("eventlet", "eventlet.websocket:RFC6455WebSocket", "_apply_mask", "use_unmask"),
    PrivateName("eventlet", "eventlet.websocket:RFC6455WebSocket", "_recv_frame",
                "fast_unmask_supported, whole_message_bound_supported"),
    PrivateName("eventlet", "eventlet.websocket:RFC6455WebSocket", "_send_closing_frame", "send_close_frame"),
    PrivateName("eventlet", "eventlet.websocket:WebSocketWSGI", "_handle_hybi_request", "hooked_websocket_class"),
    PrivateName("python-engineio", "engineio.async_drivers.eventlet", "_async", "wrap_websocket_class"),
    PrivateName("python-socketio", "socketio:Server", "_handle_eio_message", "intercept_engine_messages"),
    PrivateName("python-socketio", "socketio:Server", "_trigger_event", "run_connect_handler"),
)


def _minor(version: str) -> tuple[int, int]:
    parts = version.split(".")
    try:
        return int(parts[0]), int(parts[1])
    except (IndexError, ValueError):
        return (-1, -1)


def fast_unmask_supported(version: str | None = None) -> tuple[bool, str]:
    """Whether :func:`use_unmask` may replace eventlet's unmask, and why not if it may not.

    Reads ``RFC6455WebSocket._apply_mask`` (a staticmethod ``(data, mask, length, offset)``) and the SOURCE
    of ``RFC6455WebSocket._recv_frame`` (it must unmask through ``self._apply_mask(``), so an instance
    attribute shadows the stock unmask for that connection only. Checked: eventlet 0.35 to 0.41
    (``FAST_UNMASK_EVENTLET``), last against ``CHECKED_VERSIONS["eventlet"]``.
    """
    import eventlet
    from eventlet.websocket import RFC6455WebSocket

    version = eventlet.__version__ if version is None else version
    lo, hi = FAST_UNMASK_EVENTLET
    if not lo <= _minor(version) <= hi:
        return False, f"eventlet {version} is outside the tested range {lo}..{hi}"
    original = inspect.getattr_static(RFC6455WebSocket, "_apply_mask", None)
    if not isinstance(original, staticmethod):
        return False, "RFC6455WebSocket._apply_mask is not a static method"
    if list(inspect.signature(original.__func__).parameters) != ["data", "mask", "length", "offset"]:
        return False, "RFC6455WebSocket._apply_mask has an unexpected signature"
    try:
        source = inspect.getsource(RFC6455WebSocket._recv_frame)
    except (OSError, TypeError):
        return False, "cannot read RFC6455WebSocket._recv_frame to check it"
    if "self._apply_mask(" not in source:
        return False, "RFC6455WebSocket._recv_frame does not unmask through self._apply_mask"
    return True, ""


def use_unmask(ws: EventletWebSocket, unmask: Callable[..., bytes]) -> None:
    """Unmask the frames of the WebSocket ``ws`` with ``unmask`` instead of eventlet's ``_apply_mask``.

    Why: eventlet unmasks every client frame one byte at a time in Python, several milliseconds for a
    ~21 KB Unity frame. Set on the INSTANCE, shadowing the staticmethod: eventlet's class is untouched.
    Only where :func:`fast_unmask_supported`. Checked: eventlet 0.35 to 0.41, last ``CHECKED_VERSIONS``.
    """
    ws._apply_mask = unmask


def whole_message_bound_supported() -> tuple[bool, str]:
    """Whether eventlet's frame parser builds each message through ``self.Message`` (whose ``push`` then
    sees every chunk, so a bound on the whole message holds while it arrives), read from the SOURCE of
    ``RFC6455WebSocket._recv_frame``. Checked: ``CHECKED_VERSIONS["eventlet"]``."""
    from eventlet.websocket import RFC6455WebSocket

    try:
        source = inspect.getsource(RFC6455WebSocket._recv_frame)
    except (OSError, TypeError):
        return False, "cannot read RFC6455WebSocket._recv_frame"
    if "self.Message(" not in source or not hasattr(RFC6455WebSocket.Message, "push"):
        return False, "RFC6455WebSocket._recv_frame does not build messages through self.Message"
    return True, ""


def send_close_frame(ws: EventletWebSocket, code: int, reason: str) -> None:
    """Send the close frame ``code`` with ``reason`` on the eventlet WebSocket ``ws``, send errors ignored.

    Why private: eventlet's public ``close()`` sends only 1000 and blocks; the server closes a client after
    a protocol error with 1002 and its reason, then ends the session itself. Uses
    ``RFC6455WebSocket._send_closing_frame(ignore_send_errors, close_data=(code, reason))``.
    Checked: ``CHECKED_VERSIONS["eventlet"]``.
    """
    ws._send_closing_frame(True, close_data=(code, reason))


def hooked_websocket_class(base: type, name: str, on_request: Callable[[WSGIEnvironment], None] | None = None,
                           on_upgrade: Callable[[WSGIEnvironment, EventletWebSocket], None] | None = None,
                           on_end: Callable[[WSGIEnvironment], None] | None = None) -> type:
    """A subclass of engine.io's eventlet ``WebSocketWSGI`` ``base`` calling hooks around each connection.

    ``on_request(environ)`` before the WebSocket session, ``on_upgrade(environ, ws)`` once eventlet has built
    the ``RFC6455WebSocket`` (before any frame is read), ``on_end(environ)`` when the session ends however it
    ends. Why private: the upgraded socket exists only inside eventlet's ``WebSocketWSGI._handle_hybi_request``
    (overridden here); engine.io hands it to its own handler only. Checked: ``CHECKED_VERSIONS["eventlet"]``
    and ``["python-engineio"]`` (its ``WebSocketWSGI`` subclass).
    """
    from eventlet.websocket import RFC6455WebSocket

    class Hooked(base):  # type: ignore[misc]
        def __call__(self, environ: WSGIEnvironment, start_response: StartResponse) -> Iterable[bytes]:
            if on_request is not None:
                on_request(environ)
            try:
                response: Iterable[bytes] = super().__call__(environ, start_response)  # the whole WebSocket session
                return response
            finally:
                if on_end is not None:
                    on_end(environ)

        def _handle_hybi_request(self, environ: WSGIEnvironment) -> object:
            ws: object = super()._handle_hybi_request(environ)
            if on_upgrade is not None and isinstance(ws, RFC6455WebSocket):
                on_upgrade(environ, ws)
            return ws

    Hooked.__name__ = Hooked.__qualname__ = name
    return Hooked


def wrap_websocket_class(eio_server: EngineServer, wrap: Callable[[type], type]) -> None:
    """Give this ``engineio.Server`` (eventlet mode) the WebSocket class ``wrap(its current class)``.

    Why private: engine.io takes its WebSocket class from its async driver's table ``_async``, which each
    server holds by reference to the driver module's ``_async``. The server gets its own COPY with the new
    class, so the module-level table and every other server in the process stay stock.
    Checked: ``CHECKED_VERSIONS["python-engineio"]``.
    """
    table = dict(eio_server._async)
    table["websocket"] = wrap(cast(type, table["websocket"]))  # engine.io's WebSocketWSGI class
    eio_server._async = table


def intercept_engine_messages(sio: SocketServer, handler: MessageHandler) -> MessageHandler:
    """Route every engine.io message of the ``socketio.Server`` ``sio`` to ``handler(eio_sid, data)`` first;
    returns python-socketio's own handler (``Server._handle_eio_message``, bound) for it to call.

    Why: the Unity simulator never sends the CONNECT packet, and what no Socket.IO client sends must be
    refused before python-socketio parses it. python-socketio registers that private method as engine.io's
    ``message`` handler in its constructor; re-registering through engine.io's public ``on`` puts ``handler``
    in its place with no extra call per message. Checked: ``CHECKED_VERSIONS["python-socketio"]``.
    """
    stock: MessageHandler = sio._handle_eio_message
    sio.eio.on("message", handler)
    return stock


def run_connect_handler(sio: SocketServer, sid: str, environ: WSGIEnvironment) -> object:
    """Run the ``connect`` handler of ``/`` for ``sid`` as python-socketio would on a CONNECT packet.

    Why private: a client joined without a CONNECT packet (the simulator) must still get its ``connect``
    handler; ``Server._trigger_event(event, namespace, *args)`` is how python-socketio calls it.
    Checked: ``CHECKED_VERSIONS["python-socketio"]``.
    """
    return sio._trigger_event("connect", "/", sid, environ, None)
