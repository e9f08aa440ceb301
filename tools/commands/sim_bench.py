"""``rbc sim-bench``: frames/s of the headless renderer and a closed-loop lap.

Library: :mod:`tools.bench.simulator` (:func:`~tools.bench.simulator.run_sim_bench` runs a
:class:`~tools.bench.simulator.SimBenchPlan`, whose fields are this command's defaults).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.arguments import add_camera_argument
from tools.bench.simulator import SimBenchPlan, run_sim_bench
from tools.sim.vehicle.kinematic import VEHICLE_KINDS

PLAN = SimBenchPlan()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tracks", nargs="+", default=list(PLAN.tracks),
                        help=f"built-in track names or track files (default: {' '.join(PLAN.tracks)})")
    parser.add_argument("--frames", type=int, default=PLAN.frames, help="frames per timing run (default %(default)s)")
    parser.add_argument("--repeats", type=int, default=PLAN.repeats,
                        help="timing runs; the best is reported (default %(default)s)")
    parser.add_argument("--threads", type=int, default=PLAN.threads,
                        help="OpenCV threads (default %(default)s: per-core numbers)")
    add_camera_argument(parser, PLAN.camera)
    parser.add_argument("--cones", type=int, default=PLAN.cones,
                        help="cones for the lake-with-cones run (default %(default)s)")
    parser.add_argument("--seed", type=int, default=PLAN.seed, help="cone placement seed (default %(default)s)")
    parser.add_argument("--sheet", type=Path, default=PLAN.sheet,
                        help="contact sheet of sample frames (default %(default)s)")
    parser.add_argument("--no-sheet", action="store_true", help="skip the contact sheet")
    parser.add_argument("--no-lap", action="store_true", help="skip the closed-loop lap over the socket")
    parser.add_argument("--vehicles", nargs="+", choices=VEHICLE_KINDS, default=list(PLAN.vehicles),
                        help="car models for the physics, in-process and socket figures (default: all)")


def run(args: argparse.Namespace) -> int:
    run_sim_bench(SimBenchPlan(
        tracks=tuple(args.tracks), frames=args.frames, repeats=args.repeats, threads=args.threads,
        camera=args.camera, cones=args.cones, seed=args.seed, sheet=None if args.no_sheet else args.sheet,
        lap=not args.no_lap, vehicles=tuple(args.vehicles)))
    return 0
