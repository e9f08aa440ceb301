"""``rbc data stats|clean|fetch``: real Udacity-simulator recordings, in the spirit of DonkeyCar's tub tools.

``stats`` says what a recording holds before it is trained on, ``clean`` writes a log of the rows worth
keeping (pointing at the source frames, copying none), ``fetch`` gets the public recordings of the
manifest. Library: :mod:`tools.realdata`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.arguments import add_speed_unit_argument
from tools.realdata.fetch import DEFAULT_BASE_URL
from tools.realdata.recordings import TRACKS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True,
                                help="stats: a table per recording; clean: a cleaned log; fetch: the public "
                                     "recordings; "
                                     "fold: rbc train arguments holding one fold of them out")
    formatter = parser.formatter_class
    stats = sub.add_parser("stats", formatter_class=formatter, help="one line of figures per recording, and a total",
                           description="rows, frames, frame rate, sessions, steering, speed, duplicates and "
                                       "sharpness of each recording")
    stats.add_argument("dirs", type=Path, nargs="+", metavar="DIR", help="recording folders (driving_log.csv + IMG/)")
    stats.add_argument("--json", type=Path, default=None, metavar="OUT", help="also write the figures as JSON")
    stats.add_argument("--sharpness-frames", type=int, default=20, metavar="N",
                       help="centre frames (evenly spaced) whose Laplacian variance is averaged; 0: skip")
    _session_gap(stats)

    clean = sub.add_parser("clean", formatter_class=formatter, help="a log of the rows worth keeping",
                           description="write DST/driving_log.csv with the rows asked for; its image paths are the "
                                       "source frames' absolute paths, so no frame is copied")
    clean.add_argument("source", type=Path, metavar="SRC", help="recording folder (driving_log.csv + IMG/)")
    clean.add_argument("--out", type=Path, required=True, metavar="DST", help="folder to write the log(s) into")
    clean.add_argument("--rows", default="", metavar="A-B",
                       help="keep only rows A to B of the source log (1-based, inclusive; how a log of two tracks "
                            "is split)")
    clean.add_argument("--min-speed", default="0", metavar="SPEED",
                       help="drop rows recorded slower than this, e.g. 5mph or 8kmh (a bare number is in "
                            "--speed-unit); 0: keep all")
    add_speed_unit_argument(clean, "mph", "the log's speed column")
    clean.add_argument("--drop-duplicates", action="store_true", help="drop rows whose centre frame an earlier row has")
    clean.add_argument("--split-sessions", action="store_true",
                       help="one log per session, DST/session-01/ ... (sessions as in rbc data stats)")
    _session_gap(clean)
    clean.add_argument("--force", action="store_true", help="write into a non-empty DST, replacing its logs")

    fetch = sub.add_parser("fetch", formatter_class=formatter, help="get public recordings from their git repositories",
                           description="clone each selected recording of tools/realdata/public_recordings.csv without "
                                       "blobs and check out only its log and IMG/ at the recorded commit")
    fetch.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder to write DIR/NAME/ into")
    fetch.add_argument("--track", choices=TRACKS, default=None,
                       help="only the recordings of this track")
    fetch.add_argument("--name", action="append", default=None, metavar="NAME", help="only this recording (repeat)")
    fetch.add_argument("--base-url", default=DEFAULT_BASE_URL, metavar="URL",
                       help="where the repositories are: URL/owner/name")


    fold = sub.add_parser("fold", formatter_class=formatter, help="rbc train arguments holding one fold out",
                          description="print --data ROOT/NAME for the public recordings outside fold F and "
                                      "--val-data ROOT/NAME for those in it (cross-validation by driver)")
    fold.add_argument("fold", metavar="F", help="the fold to hold out (A, B, C or D: the manifest's fold column)")
    fold.add_argument("--root", default="real", metavar="DIR", help="where rbc data fetch put the recordings")


def _session_gap(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--session-gap", type=float, default=1.0, metavar="S",
                        help="a jump of the frame time stamps by more than S seconds starts a new session")


def run(args: argparse.Namespace) -> int:
    return {"stats": _stats, "clean": _clean, "fetch": _fetch, "fold": _fold}[args.action](args)


def _fold(args: argparse.Namespace) -> int:
    from tools.realdata.recordings import fold_arguments, public_recordings

    print(" ".join(fold_arguments(public_recordings(), args.root, args.fold)))
    return 0


def _stats(args: argparse.Namespace) -> int:
    from drive_server.runrecords import code_version, write_json
    from tools.console import Progress
    from tools.errors import CommandError
    from tools.realdata.stats import combine, measure, summarise
    from tools.realdata.table import format_table, notes

    if args.sharpness_frames < 0 or args.session_gap <= 0:
        raise CommandError("--sharpness-frames must be >= 0 and --session-gap > 0")
    progress, measures = Progress("stats", unit="recording"), []
    try:
        for i, folder in enumerate(args.dirs):
            measures.append(measure(folder, args.sharpness_frames, args.session_gap))
            progress(i + 1, len(args.dirs))
    finally:
        progress.close()
    rows, total = [summarise(m) for m in measures], summarise(combine(measures))
    print(format_table(rows, total))
    for line in notes(total):
        print(line)
    if args.json:
        write_json(args.json, {"code_version": code_version(), "session_gap_s": args.session_gap,
                               "sharpness_frames": args.sharpness_frames,
                               "recordings": [r.as_dict() for r in rows], "total": total.as_dict()})
    return 0


def _clean(args: argparse.Namespace) -> int:
    from protocol.units import to_kmh
    from tools.arguments import parse_speed
    from tools.errors import CommandError
    from tools.realdata.clean import CleanOptions, clean, describe
    from tools.realdata.rows import parse_rows

    if args.session_gap <= 0:
        raise CommandError("--session-gap must be > 0")
    try:
        rows = parse_rows(args.rows)
    except ValueError as exc:
        raise CommandError(f"--{exc}") from None
    speed, unit = parse_speed(args.min_speed, args.speed_unit)
    options = CleanOptions(rows=rows, min_speed_kmh=to_kmh(speed, unit), min_speed_text=f"{speed:g} {unit}",
                           speed_unit=args.speed_unit, drop_duplicates=args.drop_duplicates,
                           split_sessions=args.split_sessions, session_gap_s=args.session_gap)
    print(describe(clean(args.source, args.out, options, force=args.force), options))
    return 0


def _fetch(args: argparse.Namespace) -> int:
    from tools.console import Progress
    from tools.errors import CommandError
    from tools.realdata.fetch import fetch
    from tools.realdata.recordings import public_recordings, select

    chosen = select(public_recordings(), args.track, args.name)
    if not chosen:
        raise CommandError(f"no public recording of track {args.track} among those named")
    progress, failed = Progress("fetch", unit="recording"), []
    try:
        for i, rec in enumerate(chosen):
            try:
                print(fetch(rec, args.out, args.base_url).describe(rec, args.base_url), flush=True)
            except CommandError as exc:
                print(f"{rec.name}: not fetched: {exc}", flush=True)
                failed.append((rec.name, exc))
            progress(i + 1, len(chosen))
    finally:
        progress.close()
    if failed:
        name, exc = failed[0]
        raise CommandError(f"{len(failed)} of {len(chosen)} recordings not fetched; first: {name}: {exc}", exc.hint)
    return 0
