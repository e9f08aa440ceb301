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
