"""The live view in a real browser: headless Chromium (the OS package) driven by Playwright for Python.

The real drive_server, driven by Unity-wire clients; the page must follow the loop without disturbing it.
Skipped with a reason where no browser is installed (see the README: Live view).
"""

from __future__ import annotations

import json
import shutil
import threading
import time
import urllib.request
from pathlib import Path

import pytest

from tools.wire.frames import log_frames
from tools.wire.server_process import ServerProcess
from tools.wire.unity_client import UnityWireClient

sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install -e '.[dev]')")
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium: apt-get install chromium (see README)")
SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
#: What the project's machines need to start Chromium headless with no network (see the env notes).
CHROMIUM_ARGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


class Simulator(threading.Thread):
    """A Unity-wire client at ~30 Hz, counting its replies (the loop the page must not disturb)."""

    def __init__(self, url: str, payloads: list[dict]) -> None:
        super().__init__(daemon=True)
        self.url, self.payloads = url, payloads
        self.replies = 0
        self.stop = threading.Event()
        self.failure: BaseException | None = None

    def run(self) -> None:
        try:
            with UnityWireClient(self.url) as client:
                k = 0
                while not self.stop.is_set():
                    client.exchange(self.payloads[k % len(self.payloads)])
                    self.replies += 1
                    k += 1
                    time.sleep(1 / 30)
        except BaseException as exc:  # reported by the test
            self.failure = exc


@pytest.fixture(scope="module")
def server(shallow_onnx, tmp_path_factory):
    stats = tmp_path_factory.mktemp("dash") / "stats.json"
    srv = ServerProcess(shallow_onnx, ["--log-every", "0"], stats_json=stats)
    srv.url = srv.start()
    yield srv
    srv.cleanup()


@pytest.fixture(scope="module")
def browser():
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


def _frames_on_page(page, sid_index: int = 0) -> int:
    cells = page.locator(".client .c-frames")
    return int(cells.nth(sid_index).inner_text())


def test_the_page_follows_the_loop_and_closing_it_disturbs_nothing(server, browser, tmp_path):
    payloads = [f.payload() for f in log_frames(SAMPLE)[:8]]
    sim = Simulator(server.url, payloads)
    sim.start()
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    page.goto(server.url + "/")
    page.wait_for_selector(".client .c-frames")
    first = _frames_on_page(page)
    page.wait_for_function("n => Number(document.querySelector('.client .c-frames').textContent) > n + 10", arg=first)
    assert _frames_on_page(page) > first  # the counter advances
    # the numbers on the page are the server's: frames within what was answered by then
    shown, answered = _frames_on_page(page), sim.replies
    assert 0 < shown <= answered + 2
    assert page.locator(".client img").first.get_attribute("src").startswith("data:image/jpeg;base64,/9j/")
    assert "simplistic" in page.locator("#model").inner_text() or "shallow" in page.locator("#model").inner_text()

    # a malformed frame shows up in the counters
    with UnityWireClient(server.url) as bad:
        bad.exchange({"steering_angle": "0", "throttle": "0", "speed": "abc", "image": payloads[0]["image"]})
        bad.exchange(payloads[0])  # a good one, so its panel has a frame
        page.wait_for_function("() => document.querySelectorAll('.client').length === 2")  # a second panel
        page.wait_for_function("() => [...document.querySelectorAll('.client .c-malformed')]"
                               ".some(c => Number(c.textContent) >= 1)")
        page.wait_for_timeout(500)  # let the page draw the latest snapshot
        page.screenshot(path=str(tmp_path / "dashboard.png"), full_page=True)
    page.wait_for_function("() => document.querySelectorAll('.client').length === 1")  # it left: its panel goes

    before = sim.replies
    page.close()  # a viewer that goes away must not disturb the loop
    time.sleep(1.0)
    assert sim.replies > before + 15 and sim.failure is None
    sim.stop.set()
    sim.join(5)
    assert (tmp_path / "dashboard.png").stat().st_size > 20_000


def test_a_stuck_viewer_is_dropped_and_the_page_is_read_only(server):
    url = server.url
    for method in ("POST", "PUT", "DELETE"):
        req = urllib.request.Request(url + "/", method=method, data=b"x" if method != "DELETE" else None)
        with pytest.raises(urllib.error.HTTPError) as exc:
            urllib.request.urlopen(req, timeout=5)
        assert exc.value.code in (400, 405)
    # an event stream that is never read: the server drops it instead of waiting for it
    import socket

    host, port = url.removeprefix("http://").rsplit(":", 1)
    stuck = socket.create_connection((host, int(port)))
    stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stuck.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")
    payloads = [f.payload() for f in log_frames(SAMPLE)[:4]]
    viewers = None
    with UnityWireClient(url) as client:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # a 30 Hz simulator drives while the viewer is stuck
            for k in range(30):
                client.exchange(payloads[k % 4])
                time.sleep(1 / 30)
            viewers = _viewers_seen_by_a_new_viewer(url)
            if viewers == 1:  # only the new one: the stuck one was dropped
                break
    stuck.close()
    assert viewers == 1


def _viewers_seen_by_a_new_viewer(url: str) -> int:
    with urllib.request.urlopen(url + "/events", timeout=10) as stream:
        for raw in stream:
            if raw.startswith(b"data: "):
                return json.loads(raw[6:])["server"]["viewers"]
    raise AssertionError("no snapshot")
