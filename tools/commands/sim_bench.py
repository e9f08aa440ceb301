"""``rbc sim-bench``: frames/s of the headless renderer and a closed-loop lap.

Library: :mod:`tools.bench.simulator`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2

from tools.arguments import add_camera_argument
from tools.bench.simulator import bench_track, lap_wall_time, write_sheet
from tools.bench.vehicle_models import inprocess_loop, physics_step_costs
from tools.sim.render.camera import DEFAULT_RIG
from tools.sim.track.cones import place_cones
from tools.sim.track.files import load_track
from tools.sim.vehicle.kinematic import VEHICLE_KINDS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--tracks", nargs="+", default=["lake", "mountain"],
                        help="built-in track names or track files (default: lake mountain)")
    parser.add_argument("--frames", type=int, default=600, help="frames per timing run (default 600)")
    parser.add_argument("--repeats", type=int, default=3, help="timing runs; the best is reported (default 3)")
    parser.add_argument("--threads", type=int, default=1, help="OpenCV threads (default 1: per-core numbers)")
    add_camera_argument(parser, DEFAULT_RIG)
    parser.add_argument("--cones", type=int, default=20, help="cones for the lake-with-cones run (default 20)")
    parser.add_argument("--seed", type=int, default=1, help="cone placement seed (default 1)")
    parser.add_argument("--sheet", type=Path, default=Path("out/sim_sheet.png"),
                        help="contact sheet of sample frames (default out/sim_sheet.png)")
    parser.add_argument("--no-sheet", action="store_true", help="skip the contact sheet")
    parser.add_argument("--no-lap", action="store_true", help="skip the closed-loop lap over the socket")
    parser.add_argument("--vehicles", nargs="+", choices=VEHICLE_KINDS, default=list(VEHICLE_KINDS),
                        help="car models for the physics, in-process and socket figures (default: all)")


def run(args: argparse.Namespace) -> int:
    cv2.setNumThreads(args.threads)
    print(f"rbc sim-bench: 320x160 RGB, {args.camera} camera rig, OpenCV threads {args.threads}, "
          f"best of {args.repeats} x {args.frames} frames")
    from tools.sim.worldgen.generate import resolve_track_name

    args.tracks = [resolve_track_name(t) for t in args.tracks]  # world:SEED -> its file
    tracks = [load_track(t) for t in args.tracks]
    for track in tracks:
        bench_track(track, args)
    lake = next((t for t in tracks if t.name == "lake"), None)
    if lake is not None and args.cones:
        bench_track(lake, args, cones=place_cones(lake, args.cones, args.seed), builds=False)
    print("\nphysics per step (best of runs):")
    for line in physics_step_costs(args.repeats):
        print(line)
    print("in-process closed loop, render + JPEG + physics + referee (autopilot driving, one OpenCV thread):")
    for spec in args.tracks:
        for vehicle in args.vehicles:
            print(inprocess_loop(spec, vehicle))
    for vehicle in args.vehicles:
        report = lap_wall_time(tracks, args, vehicle)
        if report:
            print(report)
    if not args.no_sheet:
        path = write_sheet(tracks, args)
        print(f"contact sheet: {path}")
    return 0
