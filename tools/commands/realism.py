"""``rbc realism``: image statistics of headless frames against real ones, per band, with a picture.

Library: :mod:`tools.realism` (the statistics, the nearest frames, the picture).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from protocol.errors import BadValue
from protocol.runrecords import code_version, write_json


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--real", type=Path, action="append", required=True, metavar="DIR",
                   help="a recording of the real simulator (driving_log.csv + IMG/); repeat for several")
    p.add_argument("--sim", type=Path, action="append", required=True, metavar="DIR",
                   help="a headless recording (rbc collect, drive_server --record); repeat for several")
    p.add_argument("--frames", type=int, default=200,
                   help="centre frames of each side, spread evenly over its recordings (default %(default)s)")
    p.add_argument("--out", type=Path, default=None, help="the picture (PNG): real frames beside their nearest "
                   "headless frames, and histograms (pip extra: plots)")
    p.add_argument("--json", type=Path, default=None, help="every statistic of both sides and the gaps")


def run(args: argparse.Namespace) -> int:
    from tools.realism.frames import centre_frames, load_rgb, nearest
    from tools.realism.stats import frame_stats, gaps, overall_gap

    if args.frames < 2:
        raise BadValue(f"--frames must be >= 2, got {args.frames}")
    sides = {}
    for side, folders in (("real", args.real), ("sim", args.sim)):
        images = [img for img in (load_rgb(p) for p in centre_frames(folders, args.frames)) if img is not None]
        if len(images) < 2:
            raise BadValue(f"fewer than 2 decodable frames in the --{side} recordings")
        sides[side] = (images, [frame_stats(img) for img in images])
    (real, real_stats), (sim, sim_stats) = sides["real"], sides["sim"]
    found = gaps(real_stats, sim_stats)
    pairs = nearest(real, sim)
    print(f"{len(real)} real frames ({', '.join(map(str, args.real))}) against {len(sim)} headless frames "
          f"({', '.join(map(str, args.sim))})")
    print(f"{'statistic':<24} {'real mean':>10} {'real std':>9} {'headless':>10} {'gap (spreads)':>14}")
    for g in found:
        print(f"{g.key:<24} {g.real_mean:>10.3f} {g.real_std:>9.3f} {g.sim_mean:>10.3f} {g.standardized:>+14.2f}")
    total = overall_gap(found)
    worst = sorted(found, key=lambda g: -abs(g.standardized))[:5]
    print(f"overall gap (median |gap| over {len(found)} statistics): {total:.2f} spreads; widest: "
          + ", ".join(f"{g.key} {g.standardized:+.1f}" for g in worst))
    print(f"nearest-frame distance (Lab thumbnail, per pixel): median "
          f"{sorted(d for _, d in pairs)[len(pairs) // 2]:.1f}")
    if args.json is not None:
        write_json(args.json, {"code_version": code_version(), "real": [str(p) for p in args.real],
                               "sim": [str(p) for p in args.sim], "frames": args.frames, "overall_gap": total,
                               "gaps": [{**g.__dict__, "standardized": g.standardized} for g in found]})
        print(f"wrote {args.json}")
    if args.out is not None:
        try:
            from tools.realism.picture import draw
        except ImportError:
            print("no picture: matplotlib is missing (pip extra: plots)")
            return 0
        title = f"real ({len(real)} frames) against headless ({len(sim)}): overall gap {total:.2f} spreads"
        print(f"wrote {draw(real, sim, pairs, real_stats, sim_stats, found, title, args.out)}")
    return 0
