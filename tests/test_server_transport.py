"""The eventlet WebSocket tuning: equivalence with eventlet's own code, version check, scope of the patch."""

from __future__ import annotations

import os
import warnings

import pytest

from drive_server.wire import transport
from drive_server.wire.transport import TransportTuning, fast_apply_mask, supported_eventlet

warnings.filterwarnings("ignore", message=r"\s*Eventlet is deprecated")
from eventlet.websocket import RFC6455WebSocket  # noqa: E402

stock_mask = RFC6455WebSocket._apply_mask


@pytest.mark.parametrize("length", [0, 1, 2, 3, 4, 5, 7, 8, 125, 126, 4097, 21_211])
@pytest.mark.parametrize("offset", [0, 1, 2, 3, 6])
def test_fast_unmask_equals_eventlets(length, offset):
    data = os.urandom(length)
    mask = tuple(os.urandom(4))
    assert fast_apply_mask(data, mask, length=length, offset=offset) == stock_mask(data, mask, length, offset)
    assert fast_apply_mask(data, mask, offset=offset) == stock_mask(data, mask, None, offset)


def test_fast_unmask_of_a_frame_received_in_chunks():
    data, mask = os.urandom(1001), tuple(os.urandom(4))
    chunks, pos = [], 0
    for size in (3, 250, 1, 747):
        chunks.append(fast_apply_mask(data[pos:pos + size], mask, length=size, offset=pos))
        pos += size
    assert b"".join(chunks) == stock_mask(data, mask)


def test_installed_eventlet_is_supported():
    ok, why = supported_eventlet()
    assert ok, why


@pytest.mark.parametrize("version", ["0.30.2", "1.0.0", "weird"])
def test_untested_eventlet_versions_are_not_patched(version):
    ok, why = supported_eventlet(version)
    assert not ok and "range" in why


def test_install_changes_only_this_server():
    import socketio
    from engineio.async_drivers import eventlet as driver

    stock_cls = driver._async["websocket"]
    sio = socketio.Server(async_mode="eventlet")
    applied = transport.install(sio.eio, TransportTuning())
    assert applied == TransportTuning()
    assert sio.eio._async["websocket"] is not stock_cls and issubclass(sio.eio._async["websocket"], stock_cls)
    assert driver._async["websocket"] is stock_cls  # the module-level table is untouched
    assert RFC6455WebSocket._apply_mask is stock_mask  # the class is untouched
    other = socketio.Server(async_mode="eventlet")
    assert other.eio._async["websocket"] is stock_cls


def test_stock_tuning_installs_nothing():
    import socketio

    sio = socketio.Server(async_mode="eventlet")
    before = sio.eio._async
    assert transport.install(sio.eio, TransportTuning.stock()) == TransportTuning.stock()
    assert sio.eio._async is before


def test_unsupported_eventlet_falls_back_to_stock(monkeypatch, caplog):
    import socketio

    monkeypatch.setattr(transport, "supported_eventlet", lambda: (False, "eventlet 9.9 is outside the tested range"))
    sio = socketio.Server(async_mode="eventlet")
    applied = transport.install(sio.eio, TransportTuning())
    assert not applied.fast_unmask and applied.tcp_nodelay
    assert "not applied" in caplog.text
