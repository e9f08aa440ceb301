"""Hostile input at the protocol level: decompression bombs are refused from the header, numbers are strict."""

from __future__ import annotations

import base64
import struct

import cv2
import numpy as np
import pytest
from helpers_server import SAMPLE_LOG

from protocol import FRAME_HEIGHT, FRAME_WIDTH, ProtocolError, decode_image, parse_number, parse_telemetry
from protocol import jpeg as jpeg_module
from protocol.jpeg_header import image_size

REAL_JPEG = next((SAMPLE_LOG / "IMG").glob("center_*.jpg")).read_bytes()


def with_claimed_size(jpeg: bytes, width: int, height: int) -> bytes:
    """The same JPEG with its start-of-frame marker rewritten to claim ``width`` x ``height``."""
    pos = 2
    while jpeg[pos + 1] not in (0xC0, 0xC1, 0xC2):
        pos += 2 + struct.unpack_from(">H", jpeg, pos + 2)[0]
    return jpeg[:pos + 5] + struct.pack(">HH", height, width) + jpeg[pos + 9:]


def tiny_jpeg(width: int = 8, height: int = 8) -> bytes:
    ok, buf = cv2.imencode(".jpg", np.zeros((height, width, 3), np.uint8))
    assert ok
    return buf.tobytes()


def test_header_size_of_real_frames():
    assert image_size(REAL_JPEG) == (FRAME_WIDTH, FRAME_HEIGHT)
    ok, png = cv2.imencode(".png", np.zeros((7, 5, 3), np.uint8))
    assert image_size(png.tobytes()) == (5, 7)
    ok, progressive = cv2.imencode(".jpg", np.zeros((160, 320, 3), np.uint8), [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])
    assert image_size(progressive.tobytes()) == (320, 160)


@pytest.mark.parametrize("raw", [b"\xff\xd8", b"\xff\xd8\xff", b"\xff\xd8\x00\x00\x00\x00", b"\xff\xd8\xff\xda\x00\x02",
                                 b"\xff\xd8\xff\xe0\x00\x00\x00", b"\x89PNG\r\n\x1a\n\x00", b"GIF89a"])
def test_header_parser_refuses_cut_or_corrupt_headers(raw):
    with pytest.raises(ProtocolError):
        image_size(raw)


def test_decompression_bomb_is_refused_before_decoding(monkeypatch):
    """Issue #10 item 2: an ~800-byte JPEG claiming 30000x30000 pixels was decoded (2.3 s, +1.3 GB)."""
    bomb = with_claimed_size(tiny_jpeg(), 30000, 30000)
    assert len(bomb) < 1000 and image_size(bomb) == (30000, 30000)

    def no_decode(*_):
        raise AssertionError("cv2.imdecode must not be reached for a wrong-size image")

    monkeypatch.setattr(jpeg_module.cv2, "imdecode", no_decode)
    for reduce in (1, 2):
        with pytest.raises(ProtocolError, match="30000x30000"):
            decode_image(base64.b64encode(bomb).decode(), reduce=reduce)
    with pytest.raises(ProtocolError, match="321x160"):  # off by one pixel: refused from the header too
        decode_image(base64.b64encode(with_claimed_size(REAL_JPEG, 321, 160)).decode())


def test_a_real_frame_still_decodes():
    assert decode_image(base64.b64encode(REAL_JPEG).decode()).shape == (FRAME_HEIGHT, FRAME_WIDTH, 3)


@pytest.mark.parametrize("bad", [
    "1_000", "1_0", "\u0661\u0662", "\uff11\uff12", "٣.٥", "0x10", "1e5000", "Infinity", "-inf", "nan", ".", "e5",
    "1" * 65, "--1", "1,0,0", "12 34",
])
def test_numbers_are_ascii_decimal_only(bad):
    """Issue #10, lenient: ``float()`` took "1_000", Arabic-Indic and full-width digits."""
    with pytest.raises(ProtocolError):
        parse_number(bad, "speed")


@pytest.mark.parametrize("bad", ["-1e308", "-1", "1e308", "5000", -5, pytest.param(10 ** 400, id="400-digit"),
                                 1e300, -1e-3])
def test_speed_must_be_sensible(bad):
    """Issue #10, lenient: speed "-1e308" gave full throttle; a 400-digit integer overflowed float()."""
    with pytest.raises(ProtocolError, match="speed"):
        parse_number(bad, "speed")


@pytest.mark.parametrize(("text", "value"), [("0", 0.0), ("-0,0000", 0.0), ("30,5", 30.5), ("1.5E+01", 15.0),
                                             ("+2", 2.0), ("1.", 1.0), (".5", 0.5), (120, 120.0)])
def test_plausible_speeds_are_accepted(text, value):
    assert parse_number(text, "speed") == value


def test_a_huge_json_integer_in_a_telemetry_is_a_protocol_error():
    payload = {"steering_angle": "0", "throttle": "0", "speed": 10 ** 400, "image": "x"}
    with pytest.raises(ProtocolError):
        parse_telemetry(payload)
    with pytest.raises(ProtocolError):
        parse_telemetry(dict(payload, speed=0, steering_angle=-(10 ** 400)))


@pytest.mark.parametrize(("payload", "field"), [
    ([], "telemetry"),
    ({"steering_angle": "0", "throttle": "0", "speed": "0"}, "telemetry"),
    ({"steering_angle": "0", "throttle": "0", "speed": "0", "image": ""}, "image"),
    ({"steering_angle": "0", "throttle": "0", "speed": "abc", "image": "x"}, "speed"),
    ({"steering_angle": "1,5.0", "throttle": "0", "speed": "0", "image": "x"}, "steering_angle"),
    ({"steering_angle": "0", "throttle": True, "speed": "0", "image": "x"}, "throttle"),
])
def test_a_protocol_error_names_its_field_for_code(payload, field):
    """Issue 51: the server sorted faults by the text before the first ':' of the message."""
    with pytest.raises(ProtocolError) as caught:
        parse_telemetry(payload)
    assert caught.value.field == field


@pytest.mark.parametrize("image", [b"GIF89a", b"\xff\xd8\xff\xe0\x00\x00\x00", tiny_jpeg(),
                                   with_claimed_size(REAL_JPEG, 30000, 30000)])
def test_an_unusable_image_names_the_image_field(image):
    with pytest.raises(ProtocolError) as caught:
        decode_image(base64.b64encode(image).decode())
    assert caught.value.field == "image"


class _Pipeline:
    """Just what DriveServer asks of a pipeline before a frame gets as far as the model."""

    model = None

    def smoother(self):
        return None

    def client_monitor(self, sid):
        return None


@pytest.mark.parametrize(("field", "kind"), [("speed", "number"), ("throttle", "number"), ("image", "image"),
                                             ("telemetry", "payload"), ("", "payload")])
def test_the_server_counts_a_reworded_protocol_error_by_its_field(monkeypatch, field, kind):
    """Issue 51: rewording a message changed the counters (the kind was the text before its first ':')."""
    import drive_server.wire.server as server_module
    from drive_server.wire.server import DriveServer, ServerConfig

    def reworded(payload):
        raise ProtocolError("could not read this frame: the value is garbled", field=field)

    monkeypatch.setattr(server_module, "parse_telemetry", reworded)
    server = DriveServer(_Pipeline(), ServerConfig())  # type: ignore[arg-type]
    replies: list[tuple[str, dict[str, str]]] = []
    monkeypatch.setattr(server, "_reply", lambda client, event, payload: replies.append((event, payload)))
    server._on_telemetry("sid-1", {"anything": "at all"})
    assert server.clients["sid-1"].stats.bad_input == {kind: 1}
    assert [event for event, _ in replies] == ["steer"]  # answered all the same
