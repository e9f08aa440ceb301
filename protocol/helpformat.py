"""The help format of every command line of the project: each flag's help ends with its default.

In protocol, the bottom layer, because both drive_server's command line and ``rbc`` (tools) use it (stdlib only).
"""

from __future__ import annotations

import argparse


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Appends ``(default: X)`` to a flag's help unless the text already names its default."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if ("%(default)" in text or "default" in text.lower() or not action.option_strings
                or action.default in (None, False, argparse.SUPPRESS) or isinstance(action, argparse._HelpAction)):
            return text
        return text + " (default: %(default)s)"
