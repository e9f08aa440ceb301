"""``rbc sim``: drive laps of the headless simulator with a drive server or an ONNX model, print the score."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from pathlib import Path

from drive_server.serving.control import ControlLaw
from tools.arguments import add_camera_argument, add_monitor_argument, add_speed_unit_argument, add_vehicle_argument
from tools.console import Progress
from tools.errors import CommandError
from tools.sim.driving.pacing import hooks as on_frame_hooks
from tools.sim.driving.scenario import FrameEvent, ScenarioConfig
from tools.sim.driving.summary import print_summary

log = logging.getLogger("rbc.sim")


def add_arguments(p: argparse.ArgumentParser) -> None:
    who = p.add_mutually_exclusive_group(required=True)
    who.add_argument("--server", metavar="URL", help="drive server to talk to over the Unity wire "
                     "(e.g. http://127.0.0.1:4567); its own --speed-limit applies")
    who.add_argument("--model", type=Path, metavar="M.onnx", help="run this ONNX model in-process (no socket)")
    who.add_argument("--autopilot", action="store_true", help="let the scripted autopilot drive (reference)")
    d = ScenarioConfig  # the defaults, defined once
    p.add_argument("--track", default=d.track,
                   help="built-in track name, world:SEED (a generated world) or track JSON path (default %(default)s)")
    p.add_argument("--laps", type=int, default=d.laps, help="laps to drive (default %(default)s)")
    p.add_argument("--light-intensity", type=float, default=d.light_intensity,
                   help="scene light intensity (default %(default)s)")
    p.add_argument("--light-direction", type=float, default=d.light_direction_deg,
                   help="sun direction offset, degrees (default %(default)s)")
    p.add_argument("--cones", type=int, default=d.cones, help="traffic cones on the road (default %(default)s)")
    p.add_argument("--cone-seed", type=int, default=d.cone_seed, help="cone layout (default %(default)s)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--spawn-s", type=float, default=None, metavar="M", help="spawn this many metres along")
    where.add_argument("--spawn-frac", type=float, default=None, metavar="F", help="spawn at this fraction of a lap")
    p.add_argument("--yaw-offset", type=float, default=d.yaw_offset_deg, metavar="DEG",
                   help="spawn heading offset (+ = left; default %(default)s)")
    p.add_argument("--reverse", action="store_true", help="spawn facing the other way and drive the lap reversed")
    law = ControlLaw
    p.add_argument("--speed-limit", type=float, default=d.speed_limit_kmh,
                   help="speed limit in km/h of the control law for --model (v_l of Eq. 14; default %(default)s)")
    p.add_argument("--steer-limit", type=float, default=law.steer_limit_deg,
                   help="steering limit in degrees for --model: scales the model's -1..1 output "
                        "(delta of Eq. 14; default %(default)s)")
    p.add_argument("--tau", type=float, default=law.tau,
                   help="gain of the throttle/brake law for --model, 0..1 (tau of Eq. 14; default %(default)s)")
    p.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads for --model")
    add_monitor_argument(p, "with --model")
    p.add_argument("--monitor-plot", type=Path, default=None, metavar="PNG",
                   help="with --model and a monitor: its score over the run, thresholds, warnings and take-overs")
    add_speed_unit_argument(p, d.speed_unit, "the telemetry speed sent to the driver")
    add_vehicle_argument(p, d.vehicle)
    add_camera_argument(p, None)
    p.add_argument("--realtime", action="store_true",
                   help="simulated time = the driver's measured latency (default: lock-step, deterministic)")
    p.add_argument("--control-hz", type=float, default=d.control_hz,
                   help="lock-step commands per simulated second (default %(default)s)")
    p.add_argument("--seed", type=int, default=d.seed, help="camera jitter and spawn seed (default %(default)s)")
    p.add_argument("--max-lap-time", type=float, default=None, metavar="S", help="give up a lap after S sim seconds")
    p.add_argument("--json", type=Path, default=None, metavar="PATH", help="write the full result as JSON")
    p.add_argument("--map", type=Path, default=None, metavar="PNG", help="top-down trajectory map")
    p.add_argument("--strip", type=Path, default=None, metavar="IMAGE",
                   help="grid of camera frames with steering, throttle, speed and take-overs (.jpg or .png)")
    p.add_argument("--strip-every", type=float, default=8.0, metavar="S", help="strip: one frame every S seconds")
    p.add_argument("--video", type=Path, default=None, metavar="MP4",
                   help="annotated camera video (H.264 with the video extra, else mp4v)")


def _driver(args: argparse.Namespace):
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
    from tools.sim.driving.drivers import AutopilotDriver, OnnxDriver, SocketDriver

    if args.server:
        return SocketDriver(args.server)
    if args.model:
        law = ControlLaw(speed_limit_kmh=args.speed_limit, steer_limit_deg=args.steer_limit, tau=args.tau)
        return OnnxDriver(args.model, law=law, speed_unit=args.speed_unit, threads=args.threads,
                          monitor=MonitorPolicy(mode=MonitorMode(args.monitor)))
    return AutopilotDriver(speed_kmh=args.speed_limit, seed=args.seed)


def run(args: argparse.Namespace) -> int:
    from tools.sim.driving.model_rig import resolve_rig
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.session import run_scenario
    from tools.sim.track.files import get_track
    from tools.sim.worldgen.generate import resolve_track_name

    args.track = resolve_track_name(args.track)  # world:SEED -> its file
    spawn_s = args.spawn_s
    if args.spawn_frac is not None:
        spawn_s = args.spawn_frac * get_track(args.track).length
    config = ScenarioConfig(
        track=args.track, laps=args.laps, light_intensity=args.light_intensity,
        light_direction_deg=args.light_direction, cones=args.cones, cone_seed=args.cone_seed, spawn_s=spawn_s,
        yaw_offset_deg=args.yaw_offset, reverse=args.reverse, speed_limit_kmh=args.speed_limit,
        realtime=args.realtime, control_hz=args.control_hz, seed=args.seed, max_lap_time_s=args.max_lap_time,
        speed_unit=args.speed_unit, vehicle=args.vehicle, camera=resolve_rig(args.camera, args.model))
    if args.server:
        note = "speed limit: the drive server's own (--speed-limit applies to --model only)"
        if args.speed_limit != ScenarioConfig.speed_limit_kmh:
            log.warning("--speed-limit %g is ignored with --server: the drive server applies its own",
                        args.speed_limit)
    else:
        note = f"speed limit {args.speed_limit:g} km/h"

    hooks: list[Callable[[FrameEvent], None]] = []
    strip = video = None
    if args.strip:
        from tools.sim.pictures.viz import StripCollector

        strip = StripCollector(every_s=args.strip_every)
        hooks.append(strip)
    if args.video:
        from tools.sim.pictures.viz import VideoRecorder

        fps = 60.0 if args.realtime else args.control_hz
        video = VideoRecorder(args.video, fps)
        hooks.append(video)

    driver = _driver(args)
    progress = Progress(f"sim {args.track}")
    try:
        result = run_scenario(config, driver, progress=progress, on_frame=on_frame_hooks(*hooks) if hooks else None)
    except (OSError, TimeoutError) as exc:  # refused, closed or silent drive server
        raise CommandError(f"driving with {driver.name} failed: {exc}",
                           "is drive_server running at that address?" if args.server else "") from exc
    finally:
        progress.close()
        driver.close()
        if video is not None:
            video.close()
    print_summary(result, note)
    monitored = getattr(driver, "readings", None) and driver.monitor is not None
    if monitored:
        from tools.monitoreval.summary import monitor_summary

        print(monitor_summary(driver, result))
    if args.monitor_plot:
        if not monitored:
            log.warning("--monitor-plot: no monitor scored this run (a --model carrying one, --monitor warn or act)")
        else:
            from tools.monitoreval.plot import plot_run

            print(f"monitor plot {plot_run(driver, result, args.monitor_plot)}")
    if args.json:
        from protocol.runrecords import write_json

        write_json(args.json, result.to_dict())
        print(f"json  {args.json}")
    if args.map:
        from tools.sim.pictures.viz import write_trajectory_map

        print(f"map   {write_trajectory_map(result, args.map)}")
    if strip is not None and strip.frames:
        print(f"strip {strip.write(args.strip)}")
    if video is not None and video.frames:
        print(f"video {args.video} ({video.frames} frames, {video.backend})")
    if result.interrupted:
        return 130
    return 0
