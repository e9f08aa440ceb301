"""Wire format: telemetry parsing (locales, numbers, null, every malformed case) and steer encoding."""

from __future__ import annotations

import base64
import json
import math

import numpy as np
import pytest
from helpers_server import SAMPLE_LOG, jpeg_b64

from protocol import (
    FRAME_HEIGHT,
    FRAME_WIDTH,
    ProtocolError,
    SteerCommand,
    decode_image,
    encode_image,
    encode_steer,
    encode_telemetry,
    parse_number,
    parse_steer,
    parse_telemetry,
)

IMAGE = base64.b64encode(next((SAMPLE_LOG / "IMG").glob("center_*.jpg")).read_bytes()).decode("ascii")


def payload(**overrides):
    base = {"steering_angle": "-3.1250", "throttle": "0.2000", "speed": "9.0312", "image": IMAGE}
    base.update(overrides)
    return {k: v for k, v in base.items() if v is not None}


@pytest.mark.parametrize(("text", "value"), [
    ("0.25", 0.25), ("0,25", 0.25), ("-3,1250", -3.125), ("7.8E-05", 7.8e-05), (" 12 ", 12.0), ("0,0000", 0.0),
    (0.25, 0.25), (3, 3.0), (-0.0, 0.0),
])
def test_parse_number_accepts_locales_and_json_numbers(text, value):
    assert parse_number(text, "x") == pytest.approx(value)


@pytest.mark.parametrize("bad", ["abc", "", "NaN", "nan", "inf", "-Infinity", "1,000.5", None, True, [1], {"a": 1},
                                 float("nan"), float("inf")])
def test_parse_number_rejects_garbage(bad):
    with pytest.raises(ProtocolError):
        parse_number(bad, "speed")


def test_parse_telemetry_as_unity_sends_it():
    t = parse_telemetry(payload())
    assert (t.steering_angle_deg, t.throttle, t.speed) == (pytest.approx(-3.125), pytest.approx(0.2),
                                                           pytest.approx(9.0312))
    assert t.image_b64 == IMAGE


def test_parse_telemetry_comma_locale_and_numbers_as_numbers():
    assert parse_telemetry(payload(speed="9,0312", throttle="0,2000")).speed == pytest.approx(9.0312)
    t = parse_telemetry(payload(steering_angle=-3.125, throttle=0.2, speed=9))
    assert (t.steering_angle_deg, t.speed) == (-3.125, 9.0)


def test_null_payload_is_manual_mode():
    assert parse_telemetry(None) is None


@pytest.mark.parametrize("bad", [
    payload(speed="abc"), payload(speed="NaN"), payload(steering_angle=None), payload(image=None),
    payload(throttle=None, speed=None), payload(image=""), payload(image=123), [1, 2], "telemetry", 42, True,
])
def test_parse_telemetry_rejects_malformed(bad):
    with pytest.raises(ProtocolError):
        parse_telemetry(bad)


def test_decode_image_full_and_reduced():
    assert decode_image(IMAGE).shape == (FRAME_HEIGHT, FRAME_WIDTH, 3)
    assert decode_image(IMAGE, reduce=2).shape == (FRAME_HEIGHT // 2, FRAME_WIDTH // 2, 3)
    with pytest.raises(ValueError):
        decode_image(IMAGE, reduce=3)


@pytest.mark.parametrize("bad", [
    "!!!not base64!!!",                                   # bad base64 (decodes to junk: not a JPEG)
    base64.b64encode(b"GIF89a" + bytes(100)).decode(),    # not a JPEG
    base64.b64encode(b"\xff\xd8" + bytes(200)).decode(),  # JPEG magic, corrupt body
    IMAGE[: len(IMAGE) // 3],                             # truncated
    jpeg_b64(100, 50),                                    # wrong size
    "QUJD=",                                              # padding in the wrong place
])
def test_decode_image_rejects_malformed(bad):
    with pytest.raises(ProtocolError):
        decode_image(bad)


def test_encode_image_round_trip():
    img = np.full((FRAME_HEIGHT, FRAME_WIDTH, 3), (200, 30, 30), np.uint8)
    out = decode_image(encode_image(img))
    assert np.abs(out.astype(int) - img).mean() < 3  # RGB order preserved through JPEG


def test_encode_steer_strings_with_dot_never_negative_zero():
    reply = encode_steer(SteerCommand(steering=-0.125, throttle=0.2))
    assert reply == {"steering_angle": "-0.125000", "throttle": "0.200000"}
    assert all(isinstance(v, str) for v in reply.values())
    tiny = encode_steer(SteerCommand(steering=-1e-9, throttle=-0.0))
    assert tiny == {"steering_angle": "0.000000", "throttle": "0.000000"}
    assert "," not in json.dumps(encode_steer(SteerCommand(0.5, -0.5))).replace('", "', "")


def test_encode_steer_clamps_and_refuses_non_finite():
    assert encode_steer(SteerCommand(3.0, -7.0)) == {"steering_angle": "1.000000", "throttle": "-1.000000"}
    for bad in (math.nan, math.inf):
        with pytest.raises(ProtocolError):
            encode_steer(SteerCommand(bad, 0.0))


def test_parse_steer_requires_strings():
    assert parse_steer({"steering_angle": "-0.5", "throttle": "0.1"}) == SteerCommand(-0.5, 0.1)
    with pytest.raises(ProtocolError, match="string"):
        parse_steer({"steering_angle": -0.5, "throttle": "0.1"})
    with pytest.raises(ProtocolError):
        parse_steer({"throttle": "0.1"})


def test_encode_telemetry_comma_locale():
    p = encode_telemetry(-3.125, 0.2, 9.0312, IMAGE, decimal=",")
    assert p["steering_angle"] == "-3,1250" and p["speed"] == "9,0312" and p["image"] == IMAGE
    assert parse_telemetry(p).speed == pytest.approx(9.0312)
