"""Help a newcomer can use: every flag of every command explained, with its default; one name per concept."""

from __future__ import annotations

import argparse

import pytest

from drive_server.cli import build_parser as drive_server_parser
from tools.arguments import MovedToRecipe
from tools.cli import SUBCOMMANDS, load, subcommand_parser


def _parsers() -> list[tuple[str, argparse.ArgumentParser]]:
    out = [("drive_server", drive_server_parser())]
    for cmd in SUBCOMMANDS:
        if cmd.extra:
            pytest.importorskip("torch" if cmd.extra == "train" else "matplotlib")
        out.append((f"rbc {cmd.name}", subcommand_parser(cmd, load(cmd))))
    return out


def _flags(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The flags a user sees (not the hidden ones that only say where a setting moved)."""
    return [a for a in parser._actions
            if not isinstance(a, argparse._HelpAction | argparse._VersionAction | MovedToRecipe)]


def test_every_flag_of_every_command_has_help():
    missing = [f"{name} {'/'.join(a.option_strings) or a.dest}" for name, parser in _parsers()
               for a in _flags(parser) if not a.help or a.help == argparse.SUPPRESS]
    assert missing == []


def test_every_default_is_shown_in_the_help():
    hidden = []
    for name, parser in _parsers():
        formatter = parser._get_formatter()
        for action in _flags(parser):
            if not action.option_strings or action.default in (None, False):
                continue
            text = formatter._expand_help(action) if action.help else ""
            if "default" not in text.lower():
                hidden.append(f"{name} {action.option_strings[0]}")
    assert hidden == []


def test_the_speed_unit_flag_has_one_name_everywhere_and_keeps_the_old_spelling():
    for name, parser in _parsers():
        if name in ("drive_server", "rbc sim", "rbc collect"):
            flags = {s for a in parser._actions for s in a.option_strings}
            assert {"--speed-unit", "--telemetry-speed-unit"} <= flags, name
    args = drive_server_parser().parse_args(["--speed-unit", "kmh"])
    assert args.telemetry_speed_unit == "kmh"


def test_help_speaks_plain_words_before_the_papers_symbols():
    for name, parser in _parsers():
        for action in _flags(parser):
            text = action.help or ""
            assert not text.startswith(("v_l", "delta", "tau", "chi", "Eq.")), f"{name} {action.option_strings}"
