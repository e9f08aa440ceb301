"""``rbc collect``: record a Udacity-format training set with the autopilot on the headless simulator."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from tools.arguments import add_speed_unit_argument, add_vehicle_argument
from tools.console import Progress
from tools.sim.collect import CollectConfig

log = logging.getLogger("rbc.collect")


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = CollectConfig  # the defaults, defined once
    p.add_argument("--track", default=d.track, help="built-in track name or track JSON path (default %(default)s)")
    p.add_argument("--laps", type=int, default=d.laps, help="laps per direction (default %(default)s)")
    p.add_argument("--out", type=Path, required=True, help="output folder (driving_log.csv + IMG/)")
    p.add_argument("--both-directions", action="store_true",
                   help="drive the laps again in the reverse direction (the paper's simplistic data set)")
    p.add_argument("--cones", type=int, default=d.cones, help="traffic cones on the road (default %(default)s)")
    p.add_argument("--cone-seed", type=int, default=d.cone_seed, help="cone layout (default %(default)s)")
    p.add_argument("--cameras", type=int, choices=(1, 3), default=d.cameras,
                   help="1 = centre only, 3 = with left/right (default %(default)s)")
    p.add_argument("--rate-hz", type=float, default=d.rate_hz,
                   help="rows per simulated second (default %(default)s)")
    p.add_argument("--seed", type=int, default=d.seed,
                   help="autopilot reaction times and driving line (default %(default)s)")
    p.add_argument("--speed-kmh", type=float, default=d.speed_kmh,
                   help="autopilot cruising speed (default %(default)s)")
    add_speed_unit_argument(p, d.speed_unit, "the log's speed column")
    p.add_argument("--light-intensity", type=float, default=d.light_intensity,
                   help="scene light intensity (default %(default)s)")
    p.add_argument("--light-direction", type=float, default=d.light_direction_deg,
                   help="sun direction offset in degrees (default %(default)s)")
    add_vehicle_argument(p, d.vehicle)
    group = p.add_mutually_exclusive_group()
    group.add_argument("--overwrite", action="store_true", help="replace an existing log and IMG/ in --out")
    group.add_argument("--append", action="store_true", help="add rows to an existing log in --out")


def run(args: argparse.Namespace) -> int:
    from tools.sim.collect import collect

    config = CollectConfig(
        track=args.track, laps=args.laps, both_directions=args.both_directions, cones=args.cones,
        cone_seed=args.cone_seed, cameras=args.cameras, rate_hz=args.rate_hz, seed=args.seed,
        speed_kmh=args.speed_kmh, speed_unit=args.speed_unit, light_intensity=args.light_intensity,
        light_direction_deg=args.light_direction, vehicle=args.vehicle)
    progress = Progress(f"collect {args.track}")
    try:
        result = collect(config, args.out, overwrite=args.overwrite, append=args.append, progress=progress)
    finally:
        progress.close()
    rate = result.rows / result.wall_time_s if result.wall_time_s else 0.0
    laps = len(result.laps)
    print(f"log         {result.out_dir / 'driving_log.csv'}{' (interrupted)' if result.interrupted else ''}")
    print(f"rows        {result.rows} ({config.cameras} camera{'s' if config.cameras > 1 else ''}, "
          f"{config.rate_hz:g} Hz, speed in {config.speed_unit})")
    print(f"laps        {laps} on {args.track}{' in both directions' if config.both_directions else ''}, "
          f"interventions {result.interventions}")
    print(f"zero steer  {result.zero_steer_share * 100:.1f} % of rows")
    print(f"time        {result.sim_time_s:.1f} s simulated, {result.wall_time_s:.1f} s wall, {rate:.1f} rows/s")
    return 130 if result.interrupted else (1 if result.interventions else 0)
