"""The hostile campaign of ``rbc fuzz``: mixed telemetries over many short connections, every answer checked."""

from __future__ import annotations

import base64
import json
import logging
import random
import struct
import threading
from pathlib import Path

import numpy as np

from protocol import SteerCommand
from tools.wire.frames import SourceFrame as Frame
from tools.wire.unity_client import ConnectionClosed, UnityWireClient
from tools.wire.websocket import client_frame

log = logging.getLogger("rbc.fuzz")

DEFAULT_LOG = Path(__file__).resolve().parents[2] / "tests" / "data" / "udacity-sample"
WINDOW = 8  # telemetries in flight per fuzz connection (then their replies are read)
MANUAL = "manual"
STEER = "steer"



def _bomb_b64(good_b64: str, width: int = 30000, height: int = 30000) -> str:
    """A real JPEG whose start-of-frame marker claims ``width`` x ``height`` pixels."""
    raw = base64.b64decode(good_b64)
    pos = 2
    while raw[pos + 1] not in (0xC0, 0xC1, 0xC2):
        pos += 2 + struct.unpack_from(">H", raw, pos + 2)[0]
    return base64.b64encode(raw[:pos + 5] + struct.pack(">HH", height, width) + raw[pos + 9:]).decode()


def _small_jpeg_b64() -> str:
    import cv2

    ok, buf = cv2.imencode(".jpg", np.zeros((50, 100, 3), np.uint8))
    return base64.b64encode(buf.tobytes()).decode()


class Mix:
    """Telemetry events (text of the Engine.IO packet, expected reply, key of a good frame or None)."""

    def __init__(self, frames: list[Frame], rng: random.Random) -> None:
        self.rng = rng
        self.good = [f.payload() for f in frames]
        g = self.good[0]
        bomb, small = _bomb_b64(g["image"]), _small_jpeg_b64()
        event = '42["telemetry",{}]'.format
        bad_payloads: list[object] = [
            dict(g, image="!!!not base64!!!"), dict(g, image=base64.b64encode(b"GIF89a" + bytes(64)).decode()),
            dict(g, image=small), dict(g, image=bomb), dict(g, image=g["image"][: len(g["image"]) // 3]),
            dict(g, image=12), dict(g, speed="NaN"), dict(g, speed="abc"), dict(g, speed="1_000"),
            dict(g, speed="\u0661\u0662"), dict(g, speed="\uff11\uff12"), dict(g, speed="-1e308"),
            dict(g, speed="1e400"), dict(g, throttle="0,5.0"), dict(g, speed=True),
            {k: v for k, v in g.items() if k != "image"}, {"steering_angle": "0"}, {}, [1, 2, 3], "text", 42,
        ]
        self.bad = [event(json.dumps(p)) for p in bad_payloads]
        self.bad += [
            event("[" * 2000 + "]" * 2000), event(json.dumps(dict(g, speed=0))[:-1].replace('"speed": 0', '"speed": '
                                                                                          + "9" * 400) + "}"),
            event('{"speed": 1' + "0" * 5000 + "}"), '42["telemetry",{"speed":"1"', event('{"a": 1}, "extra"'),
        ]

    def telemetry(self) -> tuple[str, str, int | None]:
        r = self.rng.random()
        if r < 0.35:
            i = self.rng.randrange(len(self.good))
            payload = dict(self.good[i])
            if self.rng.random() < 0.3:  # a European locale: the same command
                payload = {k: (v.replace(".", ",") if k != "image" else v) for k, v in payload.items()}
            if self.rng.random() < 0.2:  # extra keys are ignored
                payload["extra"] = "x"
            return '42["telemetry",' + json.dumps(payload) + "]", STEER, i
        if r < 0.45:
            return '42["telemetry",null]', MANUAL, None
        return self.rng.choice(self.bad), STEER, None


#: Frames no Socket.IO client sends: each must close its connection with a close frame, and only it.
PROTOCOL_ERRORS: tuple[bytes, ...] = (
    client_frame(0x1, b"45"), client_frame(0x1, b"46"), client_frame(0x1, b"hello"), client_frame(0x1, b""),
    client_frame(0x1, b"4[[[[]]]]"),
    client_frame(0x2, b"\x00\x01binary"), client_frame(0x1, b'42["telemetry",{"image":"' + b"A" * 400_000 + b'"}]'),
    client_frame(0x1, b"4" + b"A" * 200_000, fin=False) + client_frame(0x0, b"A" * 200_000, fin=False),
)


class Tally:
    def __init__(self) -> None:
        self.sent = self.answered = self.connections = self.closed_on_error = 0
        self.mismatched = self.wrong_commands = self.lost = 0
        self.lock = threading.Lock()

    def add(self, **counts: int) -> None:
        with self.lock:
            for k, v in counts.items():
                setattr(self, k, getattr(self, k) + v)


def _reply_kind(reply: SteerCommand | None) -> str:
    return MANUAL if reply is None else STEER


def fuzz_connection(url: str, mix: Mix, reference: list[SteerCommand | None], batch: int, tally: Tally,
                    rng: random.Random) -> None:
    """One connection: ``batch`` telemetries in windows, a sentinel, then a normal close or a protocol error."""
    with UnityWireClient(url) as client:
        tally.add(connections=1)
        sent = answered = mismatched = wrong = 0
        remaining = batch
        while remaining > 0:
            window = [mix.telemetry() for _ in range(min(WINDOW, remaining))]
            remaining -= len(window)
            for text, _, _ in window:
                client.send_text(text)
            sent += len(window)
            for _, kind, good in window:
                reply = client.receive_reply(30)
                answered += 1
                if _reply_kind(reply) != kind:
                    mismatched += 1
                elif good is not None and reply != reference[good]:
                    wrong += 1
        client.send_text('42["telemetry",null]')  # a sentinel: an extra (double) answer would arrive before it
        if client.receive_reply(30) is not None:
            mismatched += 1
        tally.add(sent=sent + 1, answered=answered + 1, mismatched=mismatched, wrong_commands=wrong)
        if rng.random() < 0.35:
            client.socket.sendall(rng.choice(PROTOCOL_ERRORS))  # raw: a frame no simulator sends
            try:
                client.receive_reply(30)
            except ConnectionClosed:
                tally.add(closed_on_error=1)


def campaign(url: str, frames: list[Frame], reference: list[SteerCommand | None], total: int, seed: int,
             threads: int = 2) -> Tally:
    tally = Tally()
    per_thread = total // threads

    def worker(k: int) -> None:
        rng = random.Random(seed * 1000 + k)
        mix = Mix(frames, rng)
        done = 0
        while done < per_thread:
            batch = min(rng.randrange(50, 300), per_thread - done)
            try:
                fuzz_connection(url, mix, reference, batch, tally, rng)
            except (ConnectionClosed, TimeoutError, OSError) as exc:
                tally.add(lost=1)
                log.warning("a fuzz connection failed: %s", exc)
            done += batch

    pool = [threading.Thread(target=worker, args=(k,)) for k in range(threads)]
    for t in pool:
        t.start()
    for t in pool:
        t.join()
    return tally
