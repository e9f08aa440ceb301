"""rbc soak: its exactly-once check catches what it claims to, and a short soak holds every figure the issue names."""

from __future__ import annotations

import json

import pytest

from protocol import SteerCommand
from tools.bench.soak import Soak, SoakConfig, Tally, check_recording
from tools.cli import main

pytest.importorskip("onnx", reason="the soak's server runs a model built with the onnx package")


class ScriptedClient:
    """Replies as a server would that answered some frames twice: steers, then the sentinel's manual."""

    def __init__(self, replies: list[SteerCommand | None]) -> None:
        self.replies = list(replies)
        self.sent: list[str] = []

    def send_text(self, text: str) -> None:
        self.sent.append(text)

    def receive_reply(self, timeout: float | None = None) -> SteerCommand | None:
        if not self.replies:
            raise TimeoutError("nothing more")
        return self.replies.pop(0)


def test_a_steer_before_the_sentinels_manual_is_counted_as_an_extra_answer():
    soak = Soak("http://x", None, [], SoakConfig(duration_s=1, sample_s=1))
    tally = Tally()
    soak._sentinel(ScriptedClient([SteerCommand(0.1, 0.2), SteerCommand(0.1, 0.2), None]), tally)
    assert (tally.double_answered, tally.telemetries, tally.answered) == (2, 1, 1)
    clean = Tally()
    soak._sentinel(ScriptedClient([None]), clean)
    assert clean.double_answered == 0


def test_a_sentinel_without_its_manual_raises_for_the_client_to_count_and_reconnect():
    soak = Soak("http://x", None, [], SoakConfig(duration_s=1, sample_s=1))
    with pytest.raises(TimeoutError):
        soak._sentinel(ScriptedClient([]), Tally())


def test_check_recording_counts_rows_whose_image_is_missing_or_empty(tmp_path):
    (tmp_path / "IMG").mkdir()
    (tmp_path / "IMG" / "a.jpg").write_bytes(b"\xff\xd8")
    (tmp_path / "IMG" / "b.jpg").write_bytes(b"")
    rows = [f"{tmp_path}/IMG/{n}.jpg, , ,0,0.1,0,5\n" for n in ("a", "b", "c")]
    (tmp_path / "driving_log.csv").write_text("".join(rows))
    assert check_recording(tmp_path) == (3, 2)


def test_a_short_soak_answers_everything_once_leaks_nothing_and_records_every_image(tmp_path, shallow_onnx, capsys):
    out = tmp_path / "soak.json"
    assert main(["soak", "--duration", "8", "--clients", "2", "--sample", "2", "--model", str(shallow_onnx),
                 "--json", str(out)]) == 0
    result = json.loads(out.read_text())["result"]
    for key in ("telemetries", "unanswered", "double_answered", "rss_mib_start", "rss_mib_end", "fds_start",
                "fds_end", "p99_ms_first_minute", "p99_ms_last_minute", "recorded_rows", "recorded_missing_images"):
        assert key in result, key
    assert result["telemetries"] > 100 and result["telemetries"] == result["answered"]
    assert result["unanswered"] == 0 and result["double_answered"] == 0 and result["wrong_kind"] == 0
    assert result["reconnects"] > 3 and result["malformed"] > 3 and result["idle_sessions"] >= 1
    assert result["live_events"] > 0
    assert result["recorded_rows"] > 100 and result["recorded_missing_images"] == 0
    assert result["fds_end"] <= result["fds_start"]
    assert result["server_exit_code"] == 0 and result["server_tracebacks"] == 0
    assert len(result["samples"]) == 4
    assert "every telemetry answered once" in capsys.readouterr().out
