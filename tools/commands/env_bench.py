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
    parser.add_argument("--worlds", type=int, default=0, metavar="N",
                        help="also time N episodes with a new generated world each (worlds=...), against the same "
                             "episodes with their worlds already built")
    parser.add_argument("--episode-steps", type=int, default=1000, metavar="STEPS",
                        help="steps of each episode of --worlds (default 1000: 67 simulated seconds)")
    parser.add_argument("--pool", type=int, default=1, metavar="P",
                        help="worlds in play at once with --worlds (default 1: a new world every episode)")
    parser.add_argument("--new-world-steps", type=int, default=1, metavar="S",
                        help="steps between new worlds with --worlds (default 1: a new world every episode)")
    parser.add_argument("--profile", type=int, default=0, metavar="N",
                        help="also profile N steps on the first track (cProfile, by time of their own)")
    parser.add_argument("--vector", type=int, default=0, metavar="N",
                        help="also time an AsyncVectorEnv of N envs against one env on the first track, its workers "
                             "free and then pinned to a core each: scaling, CPU ms per step of each process, "
                             "workers' peak and shared memory (Linux)")


def run(args: argparse.Namespace) -> int:
    if min(args.steps, args.repeats, args.threads, args.episode_steps, args.pool, args.new_world_steps) < 1 \
            or args.profile < 0 or args.worlds < 0 or args.vector < 0:
        raise CommandError("--steps, --repeats, --threads, --episode-steps, --pool and --new-world-steps must be "
                           ">= 1, --profile, --worlds and --vector >= 0")
    try:
        import gymnasium  # noqa: F401
    except ModuleNotFoundError as exc:
        raise CommandError("rbc env-bench needs the package 'gymnasium'", 'pip install -e ".[gym]"') from exc
    import cv2

    from tools.bench.envs import HEADER, WORLDS_HEADER, bench_env_isolated, bench_worlds, profile_env

    cv2.setNumThreads(args.threads)
    print(f"rbc env-bench: rbc/Drive-v0, autopilot driving, OpenCV threads {args.threads}, "
          f"best of {args.repeats} x {args.steps} steps; each row in a process of its own (peak MB: its peak "
          f"resident memory)")
    print(HEADER)
    for track in args.tracks:
        for cameras, jpeg, observation in ((1, True, "frame"), (1, False, "frame"), (3, True, "frame"),
                                           (1, True, "model"), (1, False, "model")):
            print(bench_env_isolated(track, cameras, jpeg, args.steps, args.repeats, observation=observation,
                                     threads=args.threads).row(), flush=True)
    if args.worlds:
        every = "every episode" if args.new_world_steps == 1 else f"after every {args.new_world_steps:,} steps"
        print(f"\nseconds per episode of {args.episode_steps} steps from a random spawn, {args.worlds} episodes, "
              f"pool of {args.pool} generated world{'s' if args.pool > 1 else ''}, a new one {every}:")
        print(WORLDS_HEADER)
        base, *others = bench_worlds(args.worlds, args.episode_steps, pool=args.pool,
                                     new_world_steps=args.new_world_steps)
        print(base.row())
        for result in others:
            print(result.row(base), flush=True)
    if args.vector:
        from tools.bench.env_vector import bench_vector

        print(f"\nAsyncVectorEnv of {args.vector} on {args.tracks[0]} (one camera, JPEG round trip), "
              f"{args.steps} steps, against one env (each env: OpenCV threads 1):")
        for line in bench_vector(args.tracks[0], args.vector, args.steps).lines():
            print(line, flush=True)
    if args.profile:
        print(f"\ncProfile of {args.profile} steps on {args.tracks[0]} (one camera, JPEG round trip):")
        print(profile_env(args.tracks[0], args.profile))
    return 0
