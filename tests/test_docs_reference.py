"""The reference pages name every command and the Gymnasium environment's API."""

from __future__ import annotations

from pathlib import Path

import pytest

from tools.cli import SUBCOMMANDS

REPO = Path(__file__).resolve().parents[1]


def test_the_commands_table_has_every_subcommand():
    """Was: rbc dagger, env-bench, mirror, monitor and ensemble had no row."""
    page = (REPO / "docs" / "reference" / "commands.md").read_text(encoding="utf-8")
    rows = [line for line in page.splitlines() if line.startswith("| `rbc ")]
    missing = [c.name for c in SUBCOMMANDS
               if not any(f"`rbc {c.name}`" in row or f"`rbc {c.name} " in row for row in rows)]
    assert missing == []


def test_the_api_reference_has_the_gymnasium_environment():
    pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")
    from tools.docsite import API, api_markdown

    assert {"tools.envs.drive_env:DriveEnv", "tools.envs.config:DriveEnvConfig", "tools.envs.config:RewardConfig",
            "tools.envs.expert:ExpertPolicy", "tools.envs.policy:OnnxPolicy"} <= set(API)
    page = api_markdown()
    assert "## `DriveEnvConfig`" in page and "| `reward` |" in page and "`tools.envs.expert`" in page
