"""``rbc fuzz`` runs end to end on a small campaign: every telemetry answered once, no wrong command, no crash."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from helpers_server import REPO

pytestmark = pytest.mark.slow


def test_rbc_fuzz_small_campaign(tmp_path):
    out = tmp_path / "fuzz.json"
    proc = subprocess.run([sys.executable, "-m", "tools.cli", "fuzz", "--telemetries", "600", "--healthy", "2",
                           "--duration", "1", "--json", str(out)], capture_output=True, text=True, timeout=180,
                          cwd=REPO)
    assert proc.returncode == 0, proc.stdout + proc.stderr[-3000:]
    result = json.loads(out.read_text())
    campaign = result["campaign"]
    assert campaign["sent"] == campaign["answered"] >= 600
    assert campaign["mismatched"] == campaign["wrong_commands"] == campaign["crashes"] == campaign["lost"] == 0
    assert result["fds"]["after_all"] <= result["fds"]["before"]
    assert "healthy 30 Hz clients beside 2 misbehaving ones" in proc.stdout
    assert "Traceback" not in proc.stdout + proc.stderr


def test_the_memory_report_of_a_server_gone_during_the_campaign():
    """Was: ``rss1 - rss0`` with the server gone (no RSS) raised a TypeError instead of reporting the crash."""
    from tools.bench.fuzz import memory_report

    assert memory_report(51.5, 50.0, 14, 12) == "RSS 51.5 MiB (+1.5 MiB), 14 open fds (baseline 12)"
    assert memory_report(None, 50.0, None, 12) == "RSS unknown, None open fds (baseline 12)"
