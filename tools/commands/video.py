"""``rbc video DIR --out run.mp4``: a browser-playable video of a recording (library:
:mod:`tools.sim.pictures.recording_video`); headless laps get the same writer through ``rbc sim --video``."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.arguments import add_speed_unit_argument
from tools.sim.pictures.recording_video import GAP_S


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", type=Path, metavar="DIR",
                        help="a recording: drive_server --record DIR, rbc collect --out DIR, or a Unity training log")
    parser.add_argument("--out", type=Path, required=True, metavar="MP4", help="video file to write")
    parser.add_argument("--fps", type=float, default=None,
                        help="frames per second (default: the recording's own rate, from its frame times)")
    add_speed_unit_argument(parser, "mph", "the log's speed column")
    parser.add_argument("--gap", type=float, default=GAP_S, metavar="S",
                        help="a pause longer than S seconds between frames is marked as an intervention")


def run(args: argparse.Namespace) -> int:
    from tools.console import Progress
    from tools.sim.pictures.recording_video import write_recording_video

    progress = Progress(f"video {args.source.name}", unit="frame")
    try:
        summary = write_recording_video(args.source, args.out, args.fps, args.speed_unit, args.gap, progress)
    finally:
        progress.close()
    print(f"video {summary.path}: {summary.frames} frames at {summary.fps:.1f} frames/s, "
          f"{summary.interventions} intervention(s) marked, {summary.backend}")
    return 0
