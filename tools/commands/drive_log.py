"""``rbc drive-log``: closed loop on a recorded real drive (NVIDIA DAVE-2's evaluation), scored by the degree
of autonomy. See :mod:`tools.drivelog`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from models.networks.runfiles import CONFIG
from tools.arguments import add_gain_argument, add_loop_rule_arguments, add_smooth_argument, serving_gain, smooth_alpha
from tools.errors import CommandError

TAKEOVER_HISTORY_S = 3.0  # seconds before each take-over that --takeovers shows

if TYPE_CHECKING:
    from tools.drivelog.loop import LoopRules


def add_arguments(p: argparse.ArgumentParser) -> None:
    from tools.drivelog.loop import LoopRules
    from tools.drivelog.track import TRACK_PROFILES

    p.add_argument("--data", type=Path, required=True, help="recording folder (driving_log.csv and IMG/)")
    who = p.add_mutually_exclusive_group()
    who.add_argument("--model", type=Path, help="ONNX model that drives (through drive_server's own pipeline)")
    who.add_argument("--baseline", choices=("recorded", "zero"),
                     help="recorded: steer as the driver did (stays on the path: the measure's sanity check); "
                          "zero: always straight (fails on curves)")
    p.add_argument("--steer-bias", type=float, default=0.0, metavar="B",
                   help="added to every steering value (a biased driver must fail: a check of the measure)")
    add_smooth_argument(p)
    add_gain_argument(p)
    add_loop_rule_arguments(p)
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
    p.add_argument("--track", choices=tuple(TRACK_PROFILES), default=None,
                   help="how the road is found: the lake's yellow edge lines, the jungle's two lanes with a dashed "
                        "centre line, the mountain's dark road between leaves and barriers (default: the track "
                        "that rbc collect's laps name, else told from the asphalt's colour)")
    part = p.add_mutually_exclusive_group()
    part.add_argument("--rows", metavar="A-B[,C-D]",
                      help="drive only these rows of the log (1-based, inclusive), each stretch from the recorded "
                           "path; the road is still found on the whole recording")
    part.add_argument("--held-out-of", type=Path, metavar="RUN_DIR",
                      help=f"drive only the rows that this training run held out for validation (its {CONFIG})")
    p.add_argument("--json", type=Path, help="write the result record here")
    p.add_argument("--strip", type=Path, default=Path("drive_log_out/strip.jpg"),
                   help="picture of synthesized views (take-overs framed in red)")
    p.add_argument("--plot", type=Path, default=Path("drive_log_out/offset.png"),
                   help="picture of the lateral offset over the log")
    p.add_argument("--takeovers", type=Path, metavar="DIR",
                   help="also write one picture per take-over into DIR: the car's views in the 3 s before it above "
                        "the driver's frames of the same moments (to tell the model's faults from the measure's)")
    p.add_argument("--calibrate", action="store_true",
                   help="instead of driving: fit the camera model to the log's side cameras and print the fit")
    p.add_argument("--calibrate-rows", type=int, default=40, metavar="N", help="rows used by --calibrate")


def run(args: argparse.Namespace) -> int:
    from protocol.datalog import read_log

    alpha = smooth_alpha(args)
    if alpha is not None and alpha < 1 and args.model is None:
        raise CommandError("--smooth smooths a model's steering", "give --model M.onnx, or leave --smooth out")
    gain = serving_gain(args)
    if gain is not None and args.model is None:
        raise CommandError("--gain multiplies a model's steering", "give --model M.onnx, or leave --gain out")
    samples, report = read_log(args.data)
    if args.calibrate:
        return _calibrate(samples, args.calibrate_rows)
    if args.model is None and args.baseline is None:
        raise CommandError("nobody to drive", "give --model M.onnx, --baseline recorded or --baseline zero")
    return _drive(args, samples)


def _rules(args: argparse.Namespace) -> LoopRules:
    """The loop's rules from the flags (they check their own ranges)."""
    from tools.drivelog.loop import LoopRules

    wheelbase = {} if args.wheelbase is None else {"wheelbase_m": args.wheelbase}
    return LoopRules(lane=args.lane, max_offset_m=args.max_offset, views=args.views,
                     speed_limit_kmh=args.speed_limit, handback_s=args.handback, **wheelbase)


def _drive(args: argparse.Namespace, samples: list) -> int:
    from protocol.runrecords import code_version, write_json
    from tools.console import Progress
    from tools.drivelog.path import recorded_drive
    from tools.drivelog.pictures import write_offset_plot, write_strip, write_takeover_strips
    from tools.drivelog.record import result_record
    from tools.drivelog.run import drive_recording
    from tools.drivelog.track import recorded_track

    rules = _rules(args)
    log = recorded_drive(samples, args.speed_unit)
    keep, rows = _chosen(args, samples)
    bars = {"road": "road edges", "loop": "drive-log"}
    run = drive_recording(log, rules, args.model, args.baseline, args.steer_bias, smooth_alpha(args),
                          wheelbase_m=args.wheelbase, bars=lambda phase: Progress(bars[phase], unit="frame"),
                          say=print, track=args.track or recorded_track(args.data), keep=keep,
                          gain=serving_gain(args), history_s=TAKEOVER_HISTORY_S if args.takeovers else 0.0)
    result, name, road, fit = run.result, run.driver, run.road, run.wheelbase_fit
    frames = len(log) if keep is None else int(keep.sum())
    fitted = None if fit is None else {"wheelbase_m": round(fit.wheelbase_m, 3), "pairs": fit.pairs,
                                       "r": round(fit.r, 3)}
    record = result_record(result, args.data, frames, name, args.steer_bias, road=road) | {
        "wheelbase_fit": fitted, "code_version": code_version(), "rows": rows}
    limit = f"at most {args.speed_limit:g} km/h" if args.speed_limit else "at the recorded speed"
    part = "" if rows is None else f" (of {len(log)}: {rows})"
    print(f"drive-log {args.data}: {frames} frames{part}, {result.frames} steps, {result.driving_time_s:.0f} s "
          f"driving {limit}, driver {name}")
    rate = f" ({record['seconds_per_takeover']:.1f} s of driving per take-over)" if result.interventions else ""
    print(f"degree of autonomy {result.eta:.1f} %  take-overs {result.interventions}{rate}")
    print(f"offset from the driver's path: rms {result.offset_rms_m:.2f} m, max {record['offset_max_m']:.2f} m")
    if run.monitor is not None:
        m = run.monitor
        leads = ", ".join(f"{x:.1f} s" for x in m["leads_s"] if x is not None)
        print(f"monitor: {m['episodes']} warning episode(s); take-overs foreseen {m['foreseen']} of "
              f"{m['takeovers_scored']}, {m['foreseen_1s']} at least 1 s ahead" + (f" (lead {leads})" if leads else ""))
        record["monitor"] = m
    if result.off_road_s:
        print(f"the recorded driver was off the road for {result.off_road_s:.1f} s of the log: the person drove "
              "there (pink), not counted")
    if result.reversing_s:
        print(f"the recorded driver reversed for {result.reversing_s:.1f} s of the log (turning round, backing "
              "away): the person drove there (pink), not counted")
    title = f"{name} on {Path(args.data).name}: eta {result.eta:.1f} %, {result.interventions} take-overs"
    print(f"strip {write_strip(result, args.strip)}")
    print(f"plot  {write_offset_plot(result, args.plot, title)}")
    if args.takeovers:
        pictures = write_takeover_strips(result, log, args.takeovers)
        print(f"take-overs {len(pictures)} picture(s) in {args.takeovers}")
    if args.json:
        write_json(args.json, record)
        print(f"json  {args.json}")
    return 0


def _chosen(args: argparse.Namespace, samples: list) -> tuple[np.ndarray | None, str | None]:
    """(a flag per sample: drive it; what was chosen, for the record) from --rows or --held-out-of; (None, None):
    every row."""
    from tools.drivelog.rows import held_out_mask, parse_row_ranges, rows_mask

    if args.rows is None and args.held_out_of is None:
        return None, None
    if args.rows is not None:  # bad rows or a run folder without a config raise BadValue: one line, with a hint
        keep, what = rows_mask(samples, parse_row_ranges(args.rows)), f"rows {args.rows}"
    else:
        keep, what = held_out_mask(samples, args.held_out_of), f"held out of {args.held_out_of}"
    if not keep.any():
        raise CommandError(f"{what}: no row of {args.data} is among them")
    stretches = int(np.sum(np.diff(np.r_[0, keep.astype(np.int8)]) == 1))
    return keep, f"{what}: {int(keep.sum())} frames in {stretches} stretches"


#: ``--calibrate`` checks the re-projection by slope on this many times its rows: a steep stretch is a few
#: rows in ten, and each of these costs a small search, not a SIFT fit.
SLOPE_ROWS_PER_ROW = 5


def _calibrate(samples: list, rows: int) -> int:
    from tools.drivelog.calibrate import fit_side, spread
    from tools.drivelog.pitch import reprojection_by_slope

    chosen = spread(samples, rows)
    if not chosen:
        raise CommandError("no row of the log has left and right frames: nothing to calibrate against")
    print(f"{'side':<6} {'matches':>7} {'pitch deg':>9} {'offset/h':>8} {'yaw deg':>7}  reprojection px  "
          f"view error (grey levels)")
    for side in ("left", "right"):
        f = fit_side(chosen, side)
        print(f"{side:<6} {f.matches:>7} {f.pitch_deg:>9.2f} {f.offset_heights:>+8.3f} {f.yaw_deg:>+7.2f}  "
              f"{f.error_unmoved_px:.2f} -> {f.error_px:.2f}     {f.view_error_unmoved:.1f} -> {f.view_error:.1f}")
    rows_by_slope = spread(samples, SLOPE_ROWS_PER_ROW * rows)
    print(f"\nthe centre frame re-projected to each side camera's place against its real frame, {len(rows_by_slope)} "
          "rows: correlation of the road rows (as it is / over flat ground / over the ground at the pitch the other "
          "side measured), by how steep the ground ahead is (its pitch off the camera's)")
    for b in reprojection_by_slope([(s.center, s.left, s.right) for s in rows_by_slope  # rows with sides only
                                    if s.left is not None and s.right is not None]):
        print(f"  {b.low_deg:g}-{b.high_deg:g} deg: {b.frames:>4} rows  "
              f"{b.unmoved:.3f} / {b.flat:.3f} / {b.pitched:.3f}")
    return 0
