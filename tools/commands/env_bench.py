"""``rbc env-bench``: steps/s of the Gymnasium environment rbc/Drive-v0 per core (library: :mod:`tools.bench.envs`)."""

from __future__ import annotations

import argparse

from tools.errors import CommandError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tracks", nargs="+", default=["lake"],
                        help="built-in track names, track files or world:SEED (default: lake)")
    parser.add_argument("--steps", type=int, default=2000, help="steps per timing run (default 2000)")
    parser.add_argument("--repeats", type=int, default=3, help="timing runs; the best is reported (default 3)")
    parser.add_argument("--threads", type=int, default=1, help="OpenCV threads (default 1: per-core numbers)")
    parser.add_argument("--profile", type=int, default=0, metavar="N",
                        help="also profile N steps on the first track (cProfile, by time of their own)")


def run(args: argparse.Namespace) -> int:
    if args.steps < 1 or args.repeats < 1 or args.threads < 1 or args.profile < 0:
        raise CommandError("--steps, --repeats and --threads must be >= 1, --profile >= 0")
    try:
        import gymnasium  # noqa: F401
    except ModuleNotFoundError as exc:
        raise CommandError("rbc env-bench needs the package 'gymnasium'", 'pip install -e ".[gym]"') from exc
    import cv2

    from tools.bench.envs import HEADER, bench_env, profile_env

    cv2.setNumThreads(args.threads)
    print(f"rbc env-bench: rbc/Drive-v0, autopilot driving, OpenCV threads {args.threads}, "
          f"best of {args.repeats} x {args.steps} steps")
    print(HEADER)
    for track in args.tracks:
        for cameras, jpeg in ((1, True), (1, False), (3, True)):
            print(bench_env(track, cameras, jpeg, args.steps, args.repeats).row(), flush=True)
    if args.profile:
        print(f"\ncProfile of {args.profile} steps on {args.tracks[0]} (one camera, JPEG round trip):")
        print(profile_env(args.tracks[0], args.profile))
    return 0
