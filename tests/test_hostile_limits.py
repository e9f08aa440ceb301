"""The packet checks and the rate-limited fault log of ``drive_server.wire.limits``, without a server."""

from __future__ import annotations

import json
import logging

import pytest

from drive_server.observing.stats import FaultCounters
from drive_server.wire.limits import FaultLog, WireLimits, close_reason, json_problem, packet_problem

TELEMETRY = '42["telemetry",' + json.dumps({"steering_angle": "-3,1250", "throttle": "0.2", "speed": "9",
                                            "image": "/9j/" + "A" * 20000}) + "]"


@pytest.mark.parametrize("packet", [TELEMETRY, '42["telemetry",null]', "40", '40{"token":"x"}', "41", "2", "3",
                                    "2probe", "3probe", "5", "6", "1", '431[{"ok":true}]'])
def test_what_clients_send_is_accepted(packet):
    assert packet_problem(packet) is None and json_problem(packet[1:]) is None


@pytest.mark.parametrize("packet", ["", "hello", "0", "45", "46", '451-["telemetry",{}]', "44{}", "4", "4[1]",
                                    "4hello", "2[[[[[[]]]]]]", "b4AAAA", b"\x00binary", "7", "3" + "x" * 50])
def test_what_no_socketio_client_sends_is_a_protocol_error(packet):
    assert packet_problem(packet) is not None


@pytest.mark.parametrize(("text", "words"), [
    ('2["telemetry",' + "[" * 33 + "]" * 33 + "]", "nested 34 deep"),
    ('2["telemetry",{"speed":' + "1" * 65 + "}]", "number longer"),
    ('2["telemetry",{"speed":"1}]', "unterminated"),
    ('2["telemetry",' + "[1," * 600 + "1" + "]" * 600 + "]", "too much JSON structure"),
])
def test_json_depth_and_number_size_are_bounded(text, words):
    assert words in json_problem(text)


def test_escaped_strings_are_skipped_too():
    assert json_problem('2["telemetry",{"image":"a\\"[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[\\\\"}]') is None


def test_fault_log_writes_one_line_per_kind_and_interval(caplog):
    counters = FaultCounters()
    faults = FaultLog(counters, interval_s=3600)
    with caplog.at_level(logging.WARNING, logger="drive_server.wire.limits"):
        for _ in range(1000):
            faults.report("protocol_error", "bad %s", "thing")
        faults.report("refused", "full")
        faults.report("frame:image", "not counted here", count=False)
    assert len(caplog.records) == 3
    assert counters.as_dict() == {"protocol_error": 1000, "refused": 1}
    faults._last.clear()
    with caplog.at_level(logging.WARNING, logger="drive_server.wire.limits"):
        faults.report("protocol_error", "bad again")
    assert "[999 more like it not logged]" in caplog.records[-1].getMessage()


def test_close_reasons_fit_a_control_frame():
    assert len(close_reason("\u0661" * 200).encode()) <= 100


@pytest.mark.parametrize("kwargs", [{"max_connections": 0}, {"header_timeout_s": 0}, {"max_pending_replies": 1},
                                    {"max_message_bytes": 10}])
def test_limits_are_checked(kwargs):
    with pytest.raises(ValueError):
        WireLimits(**kwargs)


def test_a_burst_allows_that_many_lines_per_interval_at_the_given_level(caplog):
    events = FaultLog(FaultCounters(), interval_s=3600, level=logging.INFO, burst=3)
    with caplog.at_level(logging.INFO, logger="drive_server.wire.limits"):
        for i in range(10):
            events.report("connect", "client %d", i, count=False)
    assert [r.getMessage() for r in caplog.records] == ["client 0", "client 1", "client 2"]
    assert {r.levelno for r in caplog.records} == {logging.INFO} and not events.counters.as_dict()
    events._last.clear()  # the next interval
    with caplog.at_level(logging.INFO, logger="drive_server.wire.limits"):
        events.report("connect", "client %d", 10, count=False)
    assert caplog.records[-1].getMessage() == "client 10 [7 more like it not logged]"
