"""``rbc data``: real Udacity-simulator recordings, in the spirit of DonkeyCar's tub tools.

``stats`` says what a recording holds before it is trained on, ``clean`` writes a log of the rows worth
keeping (pointing at the source frames, copying none), ``fetch`` gets the public recordings of the
manifest. Library: :mod:`tools.realdata`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from models.networks.runfiles import MODEL
from tools.arguments import add_loop_rule_arguments, add_smooth_argument, add_speed_unit_argument, smooth_alpha
from tools.drivelog.loop import LoopRules
from tools.realdata.crossval_run import CrossvalPlan, run_crossval
from tools.realdata.fetch import DEFAULT_BASE_URL
from tools.realdata.recordings import TRACKS
from tools.realdata.table import COLUMN_HELP


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True,
                                help="stats: a table per recording; clean: a cleaned log; road: the road's edges; "
                                     "fetch: the public recordings; "
                                     "fold: rbc train arguments holding one fold of them out; crossval: each "
                                     "recording scored by the model its fold was held out of")
    formatter = parser.formatter_class
    stats = sub.add_parser("stats", formatter_class=formatter, help="one line of figures per recording, and a total",
                           description="rows, frames, frame rate, sessions, steering, speed, duplicates and "
                                       "sharpness of each recording. The columns: " + COLUMN_HELP)
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


    road = sub.add_parser("road", formatter_class=formatter, help="find the road's edge lines in every centre frame",
                          description="write DIR/road_edges.csv: where the road's edge lines were in each centre frame "
                                      "(what rbc drive-log's road rule uses, and a recipe's edge_gain and "
                                      "centre_gain read)")
    road.add_argument("dirs", type=Path, nargs="*", metavar="DIR", help="recording folders (driving_log.csv + IMG/)")
    road.add_argument("--public", type=Path, metavar="ROOT",
                      help="also every recording of the public list under ROOT (where rbc data fetch put them), "
                           "each road found by its track's profile")
    road.add_argument("--speed-unit", choices=("mph", "kmh"), default="mph",
                      help="unit of the log's speed column: mph (stock Udacity simulator) or kmh (the paper's)")

    fold = sub.add_parser("fold", formatter_class=formatter, help="rbc train arguments holding one fold out",
                          description="print --data ROOT/NAME for the public recordings outside fold F and "
                                      "--val-data ROOT/NAME for those in it (cross-validation by driver)")
    fold.add_argument("fold", metavar="F", help="the fold to hold out (A, B, C or D: the manifest's fold column)")
    fold.add_argument("--root", default="real", metavar="DIR", help="where rbc data fetch put the recordings")


    cv = sub.add_parser("crossval", formatter_class=formatter, help="score each recording with its fold's model",
                        description="each public recording scored by the model trained without its fold: open loop "
                                    "(every row, centre camera) and closed loop (rbc drive-log, every track); prints "
                                    "the per-track summary and one row per recording as markdown")
    cv.add_argument("--root", type=Path, default=CrossvalPlan.root, metavar="DIR",
                    help="where rbc data fetch put the recordings (default %(default)s)")
    models = cv.add_mutually_exclusive_group(required=True)
    models.add_argument("--models", metavar="PATTERN",
                        help=f"the fold models, with {{fold}} for the fold's letter, e.g. runs/cv-{{fold}}/{MODEL}")
    models.add_argument("--recipe", metavar="FILE_OR_NAME",
                        help="train the fold models with this rbc train recipe first (each fold once: a finished "
                             "fold is never trained again, an interrupted one continues from its checkpoint), "
                             "into --runs")
    cv.add_argument("--runs", type=Path, default=CrossvalPlan.runs, metavar="DIR",
                    help="with --recipe: where the fold runs live, DIR/fold-F (default %(default)s)")
    cv.add_argument("--peer", default=None, metavar="MODEL",
                    help="also score this model (trained elsewhere) on every recording, beside the folds' models")
    cv.add_argument("--track", choices=TRACKS, default=None, help="only the recordings of this track")
    cv.add_argument("--name", action="append", default=None, metavar="NAME", help="only this recording (repeat)")
    cv.add_argument("--no-closed-loop", action="store_true",
                    help="open loop only: a few minutes for the 39 public recordings on two cores, where the closed "
                         "loop takes about 20 (with --peer)")
    add_loop_rule_arguments(cv)  # as rbc drive-log's
    add_smooth_argument(cv)
    cv.add_argument("--workers", type=int, default=CrossvalPlan.workers,
                    help="recordings scored at once (default %(default)s)")
    cv.add_argument("--json", type=Path, default=None, metavar="OUT",
                    help="also write every score as JSON, after each finished fold; its journal OUT.journal.jsonl "
                         "keeps each finished recording, so the same command started again resumes there")
    cv.add_argument("--plot", type=Path, default=None, metavar="PNG",
                    help="also draw each recording's closed-loop degree of autonomy, per track, beside the peer's "
                         "(needs matplotlib: the plots extra)")


def _session_gap(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--session-gap", type=float, default=1.0, metavar="S",
                        help="a jump of the frame time stamps by more than S seconds starts a new session")


def run(args: argparse.Namespace) -> int:
    return {"stats": _stats, "clean": _clean, "fetch": _fetch, "fold": _fold, "crossval": _crossval,
            "road": _road}[args.action](args)


def _crossval(args: argparse.Namespace) -> int:
    alpha = smooth_alpha(args)
    return run_crossval(CrossvalPlan(
        root=args.root, models=args.models, recipe=args.recipe, runs=args.runs, peer=args.peer, track=args.track,
        names=tuple(args.name) if args.name else None, closed_loop=not args.no_closed_loop,
        rules=LoopRules(lane=args.lane, max_offset_m=args.max_offset, handback_s=args.handback),  # checks its ranges
        smooth=alpha, workers=args.workers, json_out=args.json, plot=args.plot))


def _road(args: argparse.Namespace) -> int:
    from models.data.roadfile import ROAD_FILE, write_road_file
    from protocol.datalog import read_log
    from tools.console import Progress
    from tools.drivelog.path import recorded_drive
    from tools.drivelog.run import car_and_road
    from tools.errors import CommandError
    from tools.realdata.recordings import public_recordings, require_fetched

    dirs = list(args.dirs)
    if args.public:
        dirs += require_fetched(public_recordings(), args.public, "public recordings")
    if not dirs:
        raise CommandError("no recording to measure", "name recording folders, or --public ROOT for the public ones")
    for folder in dirs:
        log = recorded_drive(read_log(folder)[0], args.speed_unit)

        def road_bar(_phase: str, name: str = folder.name) -> Progress:
            return Progress(f"road {name}", unit="frame")

        _, _, road = car_and_road(log, bars=road_bar)
        assert road is not None  # car_and_road(road=True), the default, always returns the edges
        out = write_road_file(Path(folder) / ROAD_FILE, log.frames, road.left_m, road.right_m, road.measured)
        print(f"{folder}: {road.describe()} -> {out}")
    return 0


def _fold(args: argparse.Namespace) -> int:
    from tools.realdata.recordings import fold_arguments, public_recordings

    print(" ".join(fold_arguments(public_recordings(), args.root, args.fold)))
    return 0


def _stats(args: argparse.Namespace) -> int:
    from protocol.runrecords import code_version, write_json
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
    from protocol.rows import parse_rows
    from protocol.units import to_kmh
    from tools.arguments import parse_speed
    from tools.errors import CommandError
    from tools.realdata.clean import CleanOptions, clean, describe

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
        name, error = failed[0]
        raise CommandError(f"{len(failed)} of {len(chosen)} recordings not fetched; first: {name}: {error}",
                           error.hint)
    return 0
