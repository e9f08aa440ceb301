"""``rbc collect``: record a Udacity-format training set with the autopilot on the headless simulator.

With ``--worlds N`` over N procedural training worlds at once (:mod:`tools.sim.collect.worlds`).
"""

from __future__ import annotations

import argparse
import logging
import os
from dataclasses import replace
from pathlib import Path

from tools.arguments import add_camera_argument, add_speed_unit_argument, add_vehicle_argument
from tools.console import Progress, bar
from tools.errors import CommandError
from tools.sim.collect.backends import BACKENDS
from tools.sim.collect.dataset import CollectConfig

log = logging.getLogger("rbc.collect")


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = CollectConfig  # the defaults, defined once
    p.add_argument("--track", default=None,
                   help=f"built-in track name, world:SEED (a generated world) or track JSON path (default {d.track})")
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
    add_camera_argument(p, d.camera)
    group = p.add_mutually_exclusive_group()
    group.add_argument("--overwrite", action="store_true", help="replace an existing log and IMG/ in --out")
    group.add_argument("--append", action="store_true", help="add rows to an existing log in --out")
    group.add_argument("--resume", action="store_true",
                       help="continue a collection in --out stopped by Ctrl-C or a full disk, with the same flags "
                            "(its complete rows, or with --worlds its finished worlds, are kept)")
    w = p.add_argument_group("procedural worlds (instead of --track)")
    w.add_argument("--worlds", type=int, default=None, metavar="N",
                   help="collect over N generated worlds, seeds --world-seed .. +N-1, into one data set "
                        "(worlds.csv says which world every row is from; the track files go to OUT/worlds/)")
    w.add_argument("--world-seed", type=int, default=0, metavar="S", help="first world seed (default %(default)s)")
    w.add_argument("--allow-eval-worlds", action="store_true",
                   help="allow seeds outside the training range 0-999999 with --worlds or --track world:SEED "
                        "(held-out worlds: never train on them)")
    w.add_argument("--world-config", default=None, metavar="JSON",
                   help='generator settings, a JSON object of WorldGenConfig fields or a file holding one, '
                        'e.g. \'{"max_length_m": 800}\' (default: the documented distribution)')
    w.add_argument("--light-range", type=_light_range, default=None, metavar="LO:HI",
                   help="domain randomisation of the sun: each world's light intensity drawn log-uniformly "
                        "from LO..HI, e.g. 0.5:2 (recorded in worlds.csv; default: --light-intensity everywhere)")
    w.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worlds collected at once (default: all cores)")
    w.add_argument("--backend", choices=BACKENDS, default="local",
                   help="local: worker processes here; ray: one Ray task per world (pip extra: cluster)")
    w.add_argument("--address", help="with --backend ray: the cluster to join (default: a private Ray instance)")


def _light_range(text: str) -> tuple[float, float]:
    """``LO:HI`` for argparse, which turns the ArgumentTypeError into a one-line usage error."""
    from tools.sim.collect.worlds import light_range_problem

    lo, sep, hi = text.partition(":")
    try:
        values = (float(lo), float(hi)) if sep else None
    except ValueError:
        values = None
    if values is None:
        raise argparse.ArgumentTypeError(f"expected LO:HI, e.g. 0.5:2, got {text!r}")
    problem = light_range_problem(*values)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return values


def _config(args: argparse.Namespace) -> CollectConfig:
    return CollectConfig(
        track=args.track or CollectConfig.track, laps=args.laps, both_directions=args.both_directions, cones=args.cones,
        cone_seed=args.cone_seed, cameras=args.cameras, rate_hz=args.rate_hz, seed=args.seed,
        speed_kmh=args.speed_kmh, speed_unit=args.speed_unit, light_intensity=args.light_intensity,
        light_direction_deg=args.light_direction, vehicle=args.vehicle, camera=args.camera)


def _worlds(args: argparse.Namespace) -> int:
    from tools.sim.collect.worlds import WorldsConfig, collect_worlds, training_seed_problem
    from tools.sim.worldgen.config import WorldGenConfig, parse_world_config

    if args.track or args.append:
        raise CommandError("--worlds collects over generated worlds: leave out --track and --append",
                           "one --out per collection; --resume continues an interrupted one")
    problem = training_seed_problem(args.world_seed, args.worlds) if args.world_seed >= 0 and args.worlds > 0 else None
    if problem and not args.allow_eval_worlds:
        raise CommandError(problem, "choose --world-seed in the training range, or pass --allow-eval-worlds")
    if problem:
        log.warning("%s (--allow-eval-worlds given)", problem)
    generator = parse_world_config(args.world_config) if args.world_config else WorldGenConfig()
    worlds = WorldsConfig(args.world_seed, args.worlds, args.allow_eval_worlds, generator, args.light_range)
    progress = bar(args.worlds, "worlds", "world")

    def on_world(outcome, done: int, total: int) -> None:
        log.info("world %d: %d rows, %d intervention(s) (%d/%d worlds)", outcome.seed, outcome.rows,
                 outcome.interventions, done, total)
        if progress is not None:
            progress.update(done - progress.n)

    try:
        result = collect_worlds(_config(args), worlds, args.out, workers=args.workers, backend=args.backend,
                                address=args.address, overwrite=args.overwrite, resume=args.resume,
                                on_world=on_world)
    finally:
        if progress is not None:
            progress.close()
    print(f"{'world':>9}  {'rows':>6}  {'interventions':>13}  {'laps':>4}  {'simulated':>9}  {'light':>5}  "
          "track sha256")
    for o in result.outcomes:
        causes = f"  ({', '.join(f'{n} {c}' for c, n in o.causes.items())})" if o.causes else ""
        print(f"{o.seed:>9}  {o.rows:>6}  {o.interventions:>13}  {o.laps:>4}  {o.sim_time_s:>8.0f}s  "
              f"{o.light_intensity:>5.2f}  {o.track_sha256[:12]}{causes}")
    failed = [o.seed for o in result.outcomes if o.interventions]
    done = len(result.outcomes)
    resumed = f", {result.resumed} from an earlier run" if result.resumed else ""
    if result.interrupted:
        print(f"interrupted: {done} of {result.total} worlds collected{resumed}; no log written yet "
              f"(continue with the same command plus --resume)")
        return 130
    print(f"log         {result.out_dir / 'driving_log.csv'} ({result.rows} rows from {done} worlds{resumed}, "
          f"{args.cameras} camera{'s' if args.cameras > 1 else ''}; worlds.csv maps rows to worlds)")
    print(f"time        {result.wall_time_s:.1f} s wall, {args.workers} worker(s) ({args.backend})")
    if failed:
        print(f"interventions in {len(failed)} world(s): {', '.join(map(str, failed))} (the log has a jump there)")
    return 1 if failed else 0


def _refuse_held_out_world(track: str, allowed: bool) -> None:
    """``--track world:SEED`` records training data: a seed outside the training range is refused."""
    from tools.sim.collect.worlds import training_seed_problem
    from tools.sim.track.files import world_seed_of

    seed = world_seed_of(track)  # a malformed name is a TrackError: one line at the CLI's error boundary
    problem = training_seed_problem(seed, 1) if seed is not None else None
    if problem and not allowed:
        raise CommandError(problem, "choose a world in the training range, or pass --allow-eval-worlds")
    if problem:
        log.warning("%s (--allow-eval-worlds given)", problem)


def run(args: argparse.Namespace) -> int:
    if args.worlds is not None:
        return _worlds(args)
    if args.light_range:
        raise CommandError("--light-range draws a light intensity per generated world",
                           "add --worlds N, or give one --light-intensity for --track")
    from tools.sim.collect.dataset import collect
    from tools.sim.worldgen.generate import resolve_track_name

    config = _config(args)
    args.track = config.track
    _refuse_held_out_world(config.track, args.allow_eval_worlds)
    config = replace(config, track=resolve_track_name(config.track))  # world:SEED -> its file
    progress = Progress(f"collect {args.track}")
    try:
        result = collect(config, args.out, overwrite=args.overwrite, append=args.append, progress=progress,
                         resume=args.resume)
    finally:
        progress.close()
    rate = result.rows / result.wall_time_s if result.wall_time_s else 0.0
    laps = len(result.laps)
    print(f"log         {result.out_dir / 'driving_log.csv'}{' (interrupted)' if result.interrupted else ''}")
    print(f"rows        {result.rows} ({config.cameras} camera{'s' if config.cameras > 1 else ''}, "
          f"{config.rate_hz:g} Hz, speed in {config.speed_unit})")
    print(f"laps        {laps} on {args.track}{' in both directions' if config.both_directions else ''}, "
          f"take-overs {result.interventions}")
    print(f"zero steer  {result.zero_steer_share * 100:.1f} % of rows")
    print(f"time        {result.sim_time_s:.1f} s simulated, {result.wall_time_s:.1f} s wall, {rate:.1f} rows/s")
    return 130 if result.interrupted else (1 if result.interventions else 0)
