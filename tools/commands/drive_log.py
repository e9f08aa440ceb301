"""``rbc drive-log``: closed loop on a recorded real drive (NVIDIA DAVE-2's evaluation), scored by the degree
of autonomy. See :mod:`tools.drivelog`."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.arguments import add_smooth_argument, smooth_alpha
from tools.errors import CommandError


def add_arguments(p: argparse.ArgumentParser) -> None:
    from tools.drivelog.loop import LoopRules

    p.add_argument("--data", type=Path, required=True, help="recording folder (driving_log.csv and IMG/)")
    who = p.add_mutually_exclusive_group()
    who.add_argument("--model", type=Path, help="ONNX model that drives (through drive_server's own pipeline)")
    who.add_argument("--baseline", choices=("recorded", "zero"),
                     help="recorded: steer as the driver did (stays on the path: the measure's sanity check); "
                          "zero: always straight (fails on curves)")
    p.add_argument("--steer-bias", type=float, default=0.0, metavar="B",
                   help="added to every steering value (a biased driver must fail: a check of the measure)")
    add_smooth_argument(p)
    p.add_argument("--lane", choices=("road", "path"), default=LoopRules.lane,
                   help="road: a person takes over when the car's side passes an edge line of the road, found in "
                        "each recorded frame; path: when the car is --max-offset from the driver's own line (DAVE-2)")
    p.add_argument("--max-offset", type=float, default=LoopRules.max_offset_m, metavar="M",
                   help="with --lane path: metres off the driver's line at which a person takes over (DAVE-2: 1 m)")
    p.add_argument("--handback", type=float, default=LoopRules.handback_s, metavar="S",
                   help="after a take-over the person drives the recorded path S seconds before handing back (the "
                        "6 s Eq. 2 charges for it; 0: at once, as DAVE-2's simulator) (default %(default)s)")
    p.add_argument("--views", choices=("nearest", "centre"), default=LoopRules.views,
                   help="nearest: re-project the nearest of the three recorded cameras (the side ones are real views "
                        "0.95 m to each side); centre: the centre camera only (DAVE-2)")
    p.add_argument("--speed-limit", type=float, default=LoopRules.speed_limit_kmh, metavar="KMH",
                   help="the car drives at the recorded speed capped at this, km/h: drive_server's default limit, "
                        "the speed a model is deployed at (0: as recorded, often full throttle)")
    p.add_argument("--wheelbase", type=float, default=None, metavar="M",
                   help="effective wheelbase of the car, metres (default: fitted to how much the recorded frames "
                        "turn against the recorded steering)")
    p.add_argument("--speed-unit", choices=("mph", "kmh"), default="mph",
                   help="unit of the log's speed column: mph (stock Udacity simulator) or kmh (the paper's)")
    p.add_argument("--json", type=Path, help="write the result record here")
    p.add_argument("--strip", type=Path, default=Path("drive_log_out/strip.jpg"),
                   help="picture of synthesized views (take-overs framed in red)")
    p.add_argument("--plot", type=Path, default=Path("drive_log_out/offset.png"),
                   help="picture of the lateral offset over the log")
    p.add_argument("--calibrate", action="store_true",
                   help="instead of driving: fit the camera model to the log's side cameras and print the fit")
    p.add_argument("--calibrate-rows", type=int, default=40, metavar="N", help="rows used by --calibrate")


def run(args: argparse.Namespace) -> int:
    from protocol.datalog import read_log

    alpha = smooth_alpha(args)
    if alpha is not None and alpha < 1 and args.model is None:
        raise CommandError("--smooth smooths a model's steering", "give --model M.onnx, or leave --smooth out")
    samples, report = read_log(args.data)
    if args.calibrate:
        return _calibrate(samples, args.calibrate_rows)
    if args.model is None and args.baseline is None:
        raise CommandError("nobody to drive", "give --model M.onnx, --baseline recorded or --baseline zero")
    if not 0.05 <= args.max_offset <= 10:
        raise CommandError("--max-offset must be 0.05..10 metres")
    if not 0 <= args.handback <= 60:
        raise CommandError("--handback must be 0..60 seconds")
    if not 0 <= args.speed_limit <= 300:
        raise CommandError("--speed-limit must be 0..300 km/h (0: the recorded speed)")
    return _drive(args, samples)


def _drive(args: argparse.Namespace, samples: list) -> int:
    from drive_server.runrecords import code_version, write_json
    from tools.console import Progress
    from tools.drivelog.drivers import make_driver
    from tools.drivelog.loop import LoopRules, drive
    from tools.drivelog.path import recorded_drive
    from tools.drivelog.pictures import write_offset_plot, write_strip
    from tools.drivelog.record import result_record

    log = recorded_drive(samples, args.speed_unit)
    driver, name = make_driver(log, args.model, args.baseline, args.steer_bias, smooth_alpha(args))
    wheelbase, fit = _wheelbase(args, log)
    rules = LoopRules(lane=args.lane, max_offset_m=args.max_offset, views=args.views, wheelbase_m=wheelbase,
                      speed_limit_kmh=args.speed_limit, handback_s=args.handback)
    road = _road(log, rules) if rules.lane == "road" else None
    progress = Progress("drive-log", unit="frame")
    try:
        result = drive(log, driver, rules, on_step=lambda j: progress(j + 1, len(log)), road=road)
    finally:
        progress.close()
    record = result_record(result, args.data, len(log), name, args.steer_bias, road=road) | {
        "wheelbase_fit": fit, "code_version": code_version()}
    limit = f"at most {args.speed_limit:g} km/h" if args.speed_limit else "at the recorded speed"
    print(f"drive-log {args.data}: {len(log)} frames, {result.frames} steps, {result.driving_time_s:.0f} s driving "
          f"{limit}, driver {name}")
    print(f"degree of autonomy {result.eta:.1f} %  interventions {result.interventions}  "
          f"({record['seconds_per_takeover']:.1f} s of driving per take-over)  offset rms {result.offset_rms_m:.2f} m  "
          f"max {record['offset_max_m']:.2f} m")
    if result.off_road_s:
        print(f"the recorded driver was off the road for {result.off_road_s:.1f} s of the log: the person drove "
              "there (pink), not counted")
    title = f"{name} on {Path(args.data).name}: eta {result.eta:.1f} %, {result.interventions} take-overs"
    print(f"strip {write_strip(result, args.strip)}")
    print(f"plot  {write_offset_plot(result, args.plot, title)}")
    if args.json:
        write_json(args.json, record)
        print(f"json  {args.json}")
    return 0


def _road(log, rules):
    """The road's edges in every frame, with progress and a one-line summary."""
    from tools.console import Progress
    from tools.drivelog.road import estimate_road

    progress = Progress("road edges", unit="frame")
    try:
        road = estimate_road(log, rules.wheelbase_m, on_frame=progress)
    finally:
        progress.close()
    print(road.describe())
    return road


def _wheelbase(args: argparse.Namespace, log) -> tuple[float, dict | None]:
    """The car's effective wheelbase: given, or fitted to the recorded frames (default if the fit fails)."""
    from tools.drivelog.yaw import wheelbase_or_default

    if args.wheelbase is not None:
        if not 1.0 <= args.wheelbase <= 20.0:
            raise CommandError("--wheelbase must be 1..20 metres")
        return args.wheelbase, None
    wheelbase, fit = wheelbase_or_default(log)
    if fit is None:
        return wheelbase, None
    print(f"car: effective wheelbase {fit.wheelbase_m:.2f} m, fitted on {fit.pairs} frame pairs "
          f"(image turn against recorded steering: r {fit.r:.2f})")
    return fit.wheelbase_m, {"wheelbase_m": round(fit.wheelbase_m, 3), "pairs": fit.pairs, "r": round(fit.r, 3)}


def _calibrate(samples: list, rows: int) -> int:
    from tools.drivelog.calibrate import fit_side, spread

    chosen = spread(samples, rows)
    if not chosen:
        raise CommandError("no row of the log has left and right frames: nothing to calibrate against")
    print(f"{'side':<6} {'matches':>7} {'pitch deg':>9} {'offset/h':>8} {'yaw deg':>7}  reprojection px  "
          f"view error (grey levels)")
    for side in ("left", "right"):
        f = fit_side(chosen, side)
        print(f"{side:<6} {f.matches:>7} {f.pitch_deg:>9.2f} {f.offset_heights:>+8.3f} {f.yaw_deg:>+7.2f}  "
              f"{f.error_unmoved_px:.2f} -> {f.error_px:.2f}     {f.view_error_unmoved:.1f} -> {f.view_error:.1f}")
    return 0
