"""The wire's patches of eventlet, python-engineio and python-socketio live in one room, and are checked at start-up.

Only :mod:`drive_server.wire.patches` names a private attribute of those libraries (the table of names is read
from the patch module, and the table is proved complete against its source); a version outside the
checked table gets one warning line; a patched name that disappeared is refused in one line.
"""

from __future__ import annotations

import ast
import logging
import warnings
from pathlib import Path
from typing import Any

import pytest

from drive_server.wire import patches
from drive_server.wire.patches import PatchError
from drive_server.wire.patches import eventlet_engineio as wire

warnings.filterwarnings("ignore", message=patches.EVENTLET_DEPRECATION)

REPO = Path(__file__).resolve().parents[1]
PATCH_ROOM = REPO / "drive_server" / "wire" / "patches"
PRIVATE = {entry.name for entry in wire.PRIVATE_NAMES}
#: Source inspection of a library is a reach into its private parts too.
INSPECTION = {"getsource", "getsourcelines", "getattr_static"}


def _identifiers(tree: ast.AST) -> set[str]:
    """Every name the code uses: attributes, definitions, variables, keywords and exact string constants
    (``getattr(x, "_async")``); a docstring that merely mentions a name is prose, not a use."""
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            found.add(node.attr)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            found.add(node.name)
        elif isinstance(node, ast.Name):
            found.add(node.id)
        elif isinstance(node, ast.keyword | ast.arg) and (node.arg is not None):
            found.add(node.arg)
        elif isinstance(node, ast.alias):
            found.add(node.name.rsplit(".", 1)[-1])
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.isidentifier():
            found.add(node.value)
    return found


def _reaches(source: str) -> set[str]:
    return _identifiers(ast.parse(source)) & (PRIVATE | INSPECTION)


def test_no_other_module_names_a_patched_private_name_or_reads_library_source():
    outside = [path for package in ("drive_server", "protocol") for path in sorted((REPO / package).rglob("*.py"))
               if PATCH_ROOM not in path.parents]
    assert len(outside) > 20
    found = {str(path.relative_to(REPO)): sorted(names) for path in outside
             if (names := _reaches(path.read_text(encoding="utf-8")))}
    assert found == {}, "move these into drive_server/wire/patches/ (and its PRIVATE_NAMES)"


def test_the_check_sees_a_private_name_used_outside_the_patch_room():
    assert _reaches("def close(ws):\n    ws._send_closing_frame(True)\n") == {"_send_closing_frame"}
    assert _reaches("class S(Server):\n    def _handle_eio_message(self, sid, data): ...\n") == {"_handle_eio_message"}
    assert _reaches("x = getattr(server, '_async')\n") == {"_async"}
    assert _reaches("import inspect\ninspect.getsource(f)\n") == {"getsource"}
    assert _reaches('"""eventlet unmasks in _apply_mask, byte by byte."""\n') == set()


def test_the_table_lists_every_private_name_the_patch_module_uses():
    tree = ast.parse((PATCH_ROOM / "eventlet_engineio.py").read_text(encoding="utf-8"))
    own = {node.name for node in tree.body if isinstance(node, ast.FunctionDef | ast.ClassDef)}
    used = {name for name in _identifiers(tree)
            if name.startswith("_") and not name.startswith("__") and name not in own}
    assert used == PRIVATE
    assert {entry.library for entry in wire.PRIVATE_NAMES} == set(wire.CHECKED_VERSIONS)
    functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    for entry in wire.PRIVATE_NAMES:
        assert set(entry.used_by.split(", ")) <= functions, entry


def test_every_patch_function_says_what_why_and_which_versions():
    for name in ("fast_unmask_supported", "use_unmask", "whole_message_bound_supported", "send_close_frame",
                 "hooked_websocket_class", "wrap_websocket_class", "intercept_engine_messages", "run_connect_handler"):
        doc = getattr(wire, name).__doc__ or ""
        assert "Checked" in doc and "CHECKED_VERSIONS" in doc, name


def test_the_installed_versions_are_the_checked_ones_and_pass_quietly(caplog):
    caplog.set_level(logging.WARNING)
    patches.check("eventlet")
    assert caplog.records == []
    for library, versions in wire.CHECKED_VERSIONS.items():
        assert patches.installed_version(library) in versions, library


@pytest.mark.parametrize("entry", wire.PRIVATE_NAMES, ids=lambda entry: entry.name)
def test_a_patched_name_that_disappears_is_refused_in_one_line(entry, monkeypatch):
    owner = patches._resolve(entry.owner)
    monkeypatch.delattr(owner, entry.name)
    assert patches.missing_names(wire.PRIVATE_NAMES) == [entry]
    with pytest.raises(PatchError) as caught:
        patches.check("eventlet")
    message = str(caught.value)
    assert "\n" not in message
    assert entry.library in message and patches.installed_version(entry.library) in message
    assert entry.where in message
    assert entry.library in caught.value.hint


def _server() -> Any:
    from drive_server.wire.server import DriveServer, ServerConfig

    # the pipeline is not touched while the server is created: only the wire is built
    return DriveServer(None, ServerConfig())  # type: ignore[arg-type]


def test_the_drive_server_refuses_to_start_without_a_patched_name(monkeypatch):
    from socketio import Server

    _server()  # starts with the installed libraries
    monkeypatch.delattr(Server, "_trigger_event")
    with pytest.raises(PatchError, match=r"python-socketio [\d.]+ has no socketio\.Server\._trigger_event"):
        _server()


def test_an_unchecked_version_is_one_warning_line_at_start_up(monkeypatch, caplog):
    monkeypatch.setitem(wire.CHECKED_VERSIONS, "python-engineio", ("3.0.0",))
    monkeypatch.setitem(wire.CHECKED_VERSIONS, "eventlet", ("0.1.0",))
    caplog.set_level(logging.WARNING)
    server = _server()
    assert server.sio is not None  # warned, not refused
    lines = [r.getMessage() for r in caplog.records if r.name == "drive_server.wire.patches"]
    assert len(lines) == 1 and "\n" not in lines[0], lines
    installed = {lib: patches.installed_version(lib) for lib in ("eventlet", "python-engineio", "python-socketio")}
    assert f"eventlet {installed['eventlet']}" in lines[0]
    assert f"python-engineio {installed['python-engineio']}" in lines[0]
    assert f"python-socketio {installed['python-socketio']}," not in lines[0].split("(checked")[0]
    assert "not checked" in lines[0] and "drive_server.wire.patches.eventlet_engineio" in lines[0]


def test_an_unknown_backend_is_named():
    with pytest.raises(PatchError, match="no wire patches for async_mode 'asyncio'"):
        patches.check("asyncio")


def test_the_patches_change_only_the_server_they_are_given():
    import socketio
    from engineio.async_drivers import eventlet as driver

    stock = driver._async["websocket"]
    sio = socketio.Server(async_mode="eventlet")
    wire.wrap_websocket_class(sio.eio, lambda base: wire.hooked_websocket_class(base, "Hooked"))
    assert issubclass(sio.eio._async["websocket"], stock) and sio.eio._async["websocket"] is not stock
    assert driver._async["websocket"] is stock
    assert socketio.Server(async_mode="eventlet").eio._async["websocket"] is stock


def test_intercepted_messages_reach_the_handler_then_python_socketio():
    import socketio

    seen: list[tuple[str, Any]] = []
    sio = socketio.Server(async_mode="eventlet")
    stock = wire.intercept_engine_messages(sio, lambda eio_sid, data: seen.append((eio_sid, data)))
    sio.eio.handlers["message"]("abc", "2[\"x\"]")
    assert seen == [("abc", "2[\"x\"]")]
    assert stock.__func__ is socketio.Server._handle_eio_message
