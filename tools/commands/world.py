"""``rbc world``: write procedural worlds as track files, or a contact sheet of them.

Library: :mod:`tools.sim.worldgen` (``generate_world(seed)``, ``write_world(seed, path)``).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from tools.errors import CommandError
from tools.sim.worldgen import SEED_RANGES, WorldGenConfig, world_seed_range, write_world
from tools.sim.worldgen.config import seed_label
from tools.sim.worldgen.sheet import write_sheet

log = logging.getLogger("rbc.world")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, default=None,
                   help="world seed (the first of --count); default: the first seed of --range")
    p.add_argument("--range", choices=sorted(SEED_RANGES), default=None, dest="seed_range",
                   help="reserved seed range: "
                   + ", ".join(f"{k} {r.start}-{r.stop - 1}" for k, r in SEED_RANGES.items())
                   + " (with --seed S: the S-th seed of the range)")
    p.add_argument("--count", type=int, default=1, help="number of consecutive seeds (default 1)")
    p.add_argument("--out", type=Path, default=None,
                   help="track file to write (with --count > 1: a folder of world-SEED.json files)")
    p.add_argument("--sheet", type=Path, default=None, help="contact sheet PNG of the worlds (camera frames and map)")
    p.add_argument("--no-drive-check", action="store_true",
                   help="skip the autopilot check of each candidate world (faster; may give a different world)")


def run(args: argparse.Namespace) -> int:
    if args.count < 1 or args.count > 100_000:
        raise CommandError(f"--count must be 1..100000, got {args.count}")
    if args.out is None and args.sheet is None:
        raise CommandError("nothing to write", hint="give --out world.json (or a folder with --count) and/or --sheet")
    if args.seed_range is not None:
        r = world_seed_range(args.seed_range)
        offset = args.seed or 0
        if not 0 <= offset <= len(r) - args.count:
            raise CommandError(f"--seed {offset} with --count {args.count} runs past the {args.seed_range} range "
                               f"({len(r):,} seeds)")
        first = r.start + offset
    elif args.seed is None:
        raise CommandError("give --seed S or --range NAME", hint="rbc world --range eval --count 12 --out worlds/")
    else:
        first = args.seed
    if first < 0:
        raise CommandError(f"--seed must be >= 0, got {first}")
    seeds = list(range(first, first + args.count))
    if args.out is not None and args.count > 1 and args.out.is_file():
        raise CommandError(f"{args.out} is a file; --count {args.count} writes a folder of worlds")
    config = WorldGenConfig(drive_check=not args.no_drive_check)
    if args.out is not None:
        for seed in seeds:
            path = args.out if args.count == 1 else args.out / f"world-{seed}.json"
            t0 = time.perf_counter()
            write_world(seed, path, config)
            print(f"world {seed} ({seed_label(seed)}) -> {path} in {time.perf_counter() - t0:.2f} s")
    if args.sheet is not None:
        print(f"contact sheet of {len(seeds)} world(s): {write_sheet(seeds, args.sheet, config=config)}")
    return 0
