"""The Unity-wire client's framing and message text, and the frame sources (driving logs, synthetic)."""

from __future__ import annotations

import json
import os
import struct

import pytest
from helpers_server import SAMPLE_LOG

from protocol import FRAME_HEIGHT, FRAME_WIDTH, MAX_STEERING_DEG, decode_image, parse_telemetry
from protocol.websocket import xor_mask as mask_payload
from tools.wire.frames import cycle_payloads, log_frames, synthetic_frames
from tools.wire.unity_client import UnityWireClient, _frame, _json_string


def unmask_reference(data: bytes, mask: bytes) -> bytes:
    return bytes(b ^ mask[i % 4] for i, b in enumerate(data))


@pytest.mark.parametrize("n", [0, 1, 3, 4, 5, 125, 126, 65535, 65536, 70_001])
def test_mask_payload_matches_rfc6455(n):
    data, mask = os.urandom(n), os.urandom(4)
    assert mask_payload(data, mask) == unmask_reference(data, mask)
    assert mask_payload(mask_payload(data, mask), mask) == data


@pytest.mark.parametrize(("n", "header_len"), [(5, 2), (126, 4), (70_000, 10)])
def test_client_frames_are_final_masked_with_the_right_length(n, header_len):
    payload = os.urandom(n)
    frame = _frame(0x1, payload)
    assert frame[0] == 0x81 and frame[1] & 0x80
    length = frame[1] & 0x7F
    if length == 126:
        length = struct.unpack("!H", frame[2:4])[0]
    elif length == 127:
        length = struct.unpack("!Q", frame[2:10])[0]
    assert length == n
    mask = frame[header_len:header_len + 4]
    assert unmask_reference(frame[header_len + 4:], mask) == payload


@pytest.mark.parametrize("text", ["abc+/=", "", 'quote"inside', "back\\slash", "tab\tx", "é", "\x7f"])
@pytest.mark.parametrize("long", [False, True])
def test_json_string_is_valid_json(text, long):
    text = "/9j/" * 100 + text if long else text  # long strings take the fast path
    assert json.loads(_json_string(text)) == text


def test_telemetry_text_is_what_unity_sends():
    client = UnityWireClient(decimal=",")
    text = client.telemetry_text({"steering_angle": -3.125, "throttle": "0.2000", "speed": 9.0312, "image": "/9j/AB+="})
    assert text.startswith('42["telemetry",{')
    event, payload = json.loads(text[2:])
    assert event == "telemetry"
    assert payload == {"steering_angle": "-3,1250", "throttle": "0,2000", "speed": "9,0312", "image": "/9j/AB+="}
    assert client.telemetry_text(None) == '42["telemetry",null]'


def test_url_parsing():
    c = UnityWireClient("http://localhost:1234")
    assert (c.host, c.port) == ("localhost", 1234)
    assert UnityWireClient("127.0.0.1:99").port == 99
    with pytest.raises(ValueError):
        UnityWireClient("https://x")
    with pytest.raises(ValueError):
        UnityWireClient(decimal=";")


def test_log_frames_read_the_real_log_tolerantly(tmp_path):
    frames = log_frames(SAMPLE_LOG)  # Windows paths, ", " separators, no header
    assert len(frames) == 36
    assert frames[2].steering_deg == pytest.approx(-0.2095149 * 25) and frames[0].speed == pytest.approx(30.19044)
    (tmp_path / "IMG").mkdir()
    src = next((SAMPLE_LOG / "IMG").glob("center_*.jpg"))
    (tmp_path / "IMG" / "c.jpg").write_bytes(src.read_bytes())
    header = "center,left,right,steering,throttle,brake,speed\n"
    (tmp_path / "driving_log.csv").write_text(header + "IMG/c.jpg,,,0.5,1,0,20\n")
    assert len(log_frames(tmp_path)) == 1
    with pytest.raises(ValueError, match="no left camera"):
        log_frames(tmp_path, camera="left")


def test_log_frames_are_valid_telemetry():
    frames = log_frames(SAMPLE_LOG)
    t = parse_telemetry(frames[2].payload())
    assert t.steering_angle_deg == pytest.approx(-0.2095149 * MAX_STEERING_DEG, abs=1e-4)
    assert decode_image(t.image_b64).shape == (FRAME_HEIGHT, FRAME_WIDTH, 3)
    assert frames[0].payload(",")["speed"] == "30,1904"
    assert len(list(cycle_payloads(frames, 100))) == 100


def test_synthetic_frames():
    frames = synthetic_frames(3, seed=1)
    assert len(frames) == 3 and frames[0].image_b64 != frames[1].image_b64
    assert decode_image(frames[0].image_b64).shape == (FRAME_HEIGHT, FRAME_WIDTH, 3)
    assert synthetic_frames(1, seed=1)[0] == frames[0]  # deterministic
