"""Every reach into a private part of the wire's libraries (eventlet, python-engineio, python-socketio), by backend.

Why one room: the drive server leans on a few internals of these libraries (a faster WebSocket unmask,
limits enforced while a message arrives, a close frame with a code, the Unity simulator's missing CONNECT
packet). An upgrade of any of them then needs one place to read. Each backend (an engine.io
``async_mode``) has its own module in :data:`BACKENDS`, holding its patches as named functions, the
private names they use (``PRIVATE_NAMES``) and the library versions they were checked against
(``CHECKED_VERSIONS``); no other module of drive_server or protocol names a private attribute of these
libraries (``tests/test_wire_patches.py``). A second backend would be a second module beside it.

:func:`check` runs when a ``DriveServer`` is created: a version not in the table is WARNED about in one
line, not refused, because what the patches need is verified right then (every private name present, the
frame parser's source read where a patch depends on it); a private name that disappeared is refused with
a one-line :class:`PatchError` naming library, version and name.
"""

from __future__ import annotations

import importlib
import logging
import warnings
from dataclasses import dataclass
from importlib import metadata
from types import ModuleType
from typing import Protocol

from protocol.errors import UserError

log = logging.getLogger(__name__)

#: engine.io ``async_mode`` -> the module holding that backend's patches.
BACKENDS = {"eventlet": "drive_server.wire.patches.eventlet_engineio"}

#: eventlet's import-time notice; it tells a user of the server nothing (the design card keeps eventlet).
EVENTLET_DEPRECATION = r"\s*Eventlet is deprecated"


class TcpSocket(Protocol):
    """What the server does to a client's TCP socket (eventlet's ``GreenSocket`` or a plain ``socket.socket``); here,
    beside the backends' protocols of library objects that hold one, so that they need nothing of the wire above."""

    def fileno(self) -> int: ...

    def setsockopt(self, level: int, option: int, value: bytes, /) -> None: ...

    def shutdown(self, how: int, /) -> None: ...


@dataclass(frozen=True)
class PrivateName:
    """One private name a patch uses: ``owner`` is ``module`` or ``module:Class`` (where it must exist)."""

    library: str  # the distribution, as pip names it
    owner: str
    name: str
    used_by: str  # the patch function that uses it

    @property
    def where(self) -> str:
        return f"{self.owner.replace(':', '.')}.{self.name}"


class PatchError(UserError):
    """A library no longer has an internal the drive server patches: running on would misbehave."""


def backend(async_mode: str) -> ModuleType:
    """The patch module of ``async_mode``."""
    if async_mode not in BACKENDS:
        raise PatchError(f"no wire patches for async_mode {async_mode!r} (known: {', '.join(sorted(BACKENDS))})")
    return importlib.import_module(BACKENDS[async_mode])


def installed_version(library: str) -> str:
    """The installed version of a distribution, ``"unknown"`` where its metadata cannot be found."""
    try:
        return metadata.version(library)
    except metadata.PackageNotFoundError:
        return "unknown"


def unchecked_versions(checked: dict[str, tuple[str, ...]]) -> list[str]:
    """``"library version"`` for each installed library whose version is not in ``checked``."""
    found = {library: installed_version(library) for library in checked}
    return [f"{library} {version}" for library, version in found.items() if version not in checked[library]]


def _resolve(owner: str) -> object:
    module_name, _, qualname = owner.partition(":")
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=EVENTLET_DEPRECATION)
        obj: object = importlib.import_module(module_name)
    for part in filter(None, qualname.split(".")):
        obj = getattr(obj, part)
    return obj


def missing_names(names: tuple[PrivateName, ...]) -> list[PrivateName]:
    """The private names (or their owners) that the installed libraries no longer have. A name counts only
    where its owner itself defines it: eventlet's ``WebSocket`` base class, say, has a
    ``_send_closing_frame`` without the close code the patch passes."""
    missing = []
    for entry in names:
        try:
            present = entry.name in vars(_resolve(entry.owner))
        except (ImportError, AttributeError, TypeError):
            present = False
        if not present:
            missing.append(entry)
    return missing


def missing_name_error(entry: PrivateName, patches: ModuleType) -> PatchError:
    """The one-line error for a patched private name that disappeared."""
    version = installed_version(entry.library)
    good = " or ".join(patches.CHECKED_VERSIONS.get(entry.library, ())) or "a checked version"
    return PatchError(f"{entry.library} {version} has no {entry.where}, which drive_server's wire patches "
                      f"need ({patches.__name__}: {entry.used_by})",
                      hint=f"install {entry.library} {good}, or update the patch and its CHECKED_VERSIONS")


def check(async_mode: str) -> None:
    """Start-up check of ``async_mode``'s patches: one warning line for unchecked versions, a
    :class:`PatchError` for the first private name that is gone."""
    patches = backend(async_mode)
    checked: dict[str, tuple[str, ...]] = patches.CHECKED_VERSIONS
    unchecked = unchecked_versions(checked)
    if unchecked:
        log.warning("%s: wire patches not checked against this version (checked: %s); running, since every "
                    "patched name is present (read %s before relying on it)", ", ".join(unchecked),
                    ", ".join(f"{lib} {' '.join(v)}" for lib, v in checked.items()), patches.__name__)
    missing = missing_names(patches.PRIVATE_NAMES)
    if missing:
        raise missing_name_error(missing[0], patches)
