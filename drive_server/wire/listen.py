"""The listening socket: one owner per port, IPv4 or IPv6, and a plain word when the port is exposed.

Why not ``eventlet.listen``: it turns on ``SO_REUSEPORT``, so a second drive_server on a port in use
starts silently and the kernel splits the simulators between the two (two different models!). Here
the port has one owner (``SO_REUSEADDR`` only, which merely allows a restart over TIME_WAIT; on
Windows ``SO_EXCLUSIVEADDRUSE``); ``--workers`` shares its one socket explicitly, by fork.
"""

from __future__ import annotations

import errno
import ipaddress
import socket

from protocol.errors import UserError

#: Pending connections the kernel queues before ``accept``.
BACKLOG = 128
#: A socket address as ``getaddrinfo`` gives it: (host, port) for IPv4, (host, port, flowinfo, scope) for IPv6.
_Address = tuple[str, int] | tuple[str, int, int, int] | tuple[int, bytes]


class ListenError(UserError, OSError):
    """The socket cannot be opened; the message is one line meant for the user (and says what to do)."""


def _family_and_address(host: str, port: int) -> tuple[socket.AddressFamily, _Address]:
    try:
        infos = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise ListenError(f"cannot listen on {host!r}: {exc.strerror}") from None
    family, _, _, _, address = infos[0]
    return family, address


def listening_socket(host: str, port: int, backlog: int = BACKLOG) -> socket.socket:
    """A bound, listening TCP socket on ``host:port`` that no other process shares."""
    if not 0 <= port <= 65535:
        raise ListenError(f"port must be in 0..65535, got {port}")
    family, address = _family_and_address(host, port)
    try:
        sock = socket.socket(family, socket.SOCK_STREAM)
    except OSError as exc:
        if exc.errno == errno.EAFNOSUPPORT:
            raise ListenError(f"cannot listen on {host!r}: IPv6 is not available on this machine") from None
        raise ListenError(f"cannot open a socket for {host!r}: {exc.strerror or exc}") from None
    try:
        if hasattr(socket, "SO_EXCLUSIVEADDRUSE"):  # Windows: SO_REUSEADDR there would allow port stealing
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_EXCLUSIVEADDRUSE, 1)
        else:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(backlog)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise ListenError(f"cannot listen on {host}:{port}: port {port} is already in use "
                              "(another drive_server?); choose another with --port") from None
        if exc.errno == errno.EADDRNOTAVAIL:
            raise ListenError(f"cannot listen on {host}: no such address on this machine") from None
        raise ListenError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    return sock


def is_local(host: str) -> bool:
    """Whether a bound address is a loopback one (nobody else on the network can connect)."""
    address = ipaddress.ip_address(host.split("%")[0])
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return address.is_loopback


def url(sock: socket.socket) -> str:
    """``http://host:port`` of a listening socket (IPv6 addresses in brackets)."""
    host, port = sock.getsockname()[:2]
    return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"


EXPOSED_WARNING = ("the server accepts connections from other machines (bound to %s): anyone on the network can "
                   "drive the car and see its camera (use --host 127.0.0.1 to keep it local)")
