"""``rbc demo``: the whole deployment loop on a fresh machine, in one command.

Starts ``drive_server`` with a bundled model as a separate process, drives one lap of the headless
simulator against it over the Unity wire protocol, prints the degree of autonomy, lap time and
latency, and writes a trajectory map and an image strip of the lap: into ``demo_out/``, or for another model
a folder of its own (``demo_out_simplistic/``, ``demo_out_NAME/`` for ``--model NAME.onnx``), so that trying a
variant never overwrites the default demo's pictures; a rerun says when it replaced an earlier run's files.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

from protocol.facts import BEHAVIORS
from tools.arguments import add_monitor_argument, add_vehicle_argument
from tools.errors import CommandError
from tools.evaluate.experiments import SETUPS
from tools.sim.driving.scenario import ScenarioConfig

log = logging.getLogger("rbc.demo")

def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--behavior", choices=BEHAVIORS, default=None,
                   help="drive a bundled specialist on its own track (simplistic, collision: lake; rigorous: "
                        "mountain) instead of the default model, the generalist, on lake")
    p.add_argument("--model", type=Path, default=None, help="drive with this ONNX model instead of a bundled one")
    p.add_argument("--laps", type=int, default=ScenarioConfig.laps, help="laps to drive (default %(default)s)")
    p.add_argument("--speed-limit", type=float, default=ScenarioConfig.speed_limit_kmh,
                   help="drive_server --speed-limit in km/h (default %(default)s)")
    add_vehicle_argument(p, ScenarioConfig.vehicle)
    add_monitor_argument(p, "the demo's server")
    p.add_argument("--out", type=Path, default=None,
                   help="folder for the map, strip and JSON (default: demo_out; demo_out_BEHAVIOR with --behavior, "
                        "demo_out_NAME with --model NAME.onnx)")
    p.add_argument("--watch", action="store_true",
                   help="drive at the pace of the wall clock and print the live view's address, so the lap can "
                        "be watched in a browser (a 1 km lap takes about 3 minutes)")


def _default_out(behavior: str | None, model: Path | None) -> Path:
    """Where a demo writes without ``--out``: ``demo_out`` for the default model, else a folder of the model's own."""
    if model is not None:
        return Path(f"demo_out_{model.stem}")
    return Path(f"demo_out_{behavior}" if behavior else "demo_out")


def _server_latency(stats_path: Path) -> str:
    try:
        stats = json.loads(stats_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return "server stats unavailable"
    summary = stats.get("total", stats)
    total = summary.get("stages_ms", {}).get("total")
    if not total:
        return "server stats unavailable"
    return f"server pipeline (decode to command) p50 {total['p50']:.2f} ms p99 {total['p99']:.2f} ms"


def run(args: argparse.Namespace) -> int:
    from drive_server.serving.models_dir import bundled_model_path, demo_model_path
    from protocol.runrecords import write_json
    from tools.console import Progress
    from tools.sim.driving.drivers import SocketDriver
    from tools.sim.driving.model_rig import model_rig
    from tools.sim.driving.pacing import WallClockPacer, hooks
    from tools.sim.driving.session import run_scenario
    from tools.sim.driving.summary import print_summary
    from tools.sim.pictures.viz import StripCollector, write_trajectory_map
    from tools.wire.server_process import ServerProcess, ServerStartError

    model = args.model or (bundled_model_path(args.behavior) if args.behavior else demo_model_path())
    if not model.is_file():
        raise CommandError(f"model not found: {model}", "pass --model PATH to an .onnx file")
    out: Path = args.out or _default_out(args.behavior, args.model)
    replacing = (out / "result.json").is_file()
    out.mkdir(parents=True, exist_ok=True)
    stats_path = out / "server_stats.json"
    setup = SETUPS[args.behavior or "simplistic"]  # a specialist's training scene; the generalist's: lake
    config = ScenarioConfig(track=setup.track, cones=setup.cones, cone_seed=setup.cone_seed, laps=args.laps,
                            speed_limit_kmh=args.speed_limit, vehicle=args.vehicle, camera=model_rig(model))
    strip = StripCollector(every_s=8.0)
    server = ServerProcess(model, ["--speed-limit", str(args.speed_limit), "--log-every", "0",
                                   "--monitor", args.monitor], stats_json=stats_path)
    try:
        url = server.start()
    except ServerStartError as exc:
        raise CommandError(str(exc)) from exc
    print(f"drive_server {model.name} listening on {url}", flush=True)
    print(f"driving {args.laps} lap{'' if args.laps == 1 else 's'} of {config.track} ({config.vehicle} car)",
          flush=True)
    if args.watch:
        print(f"watch it live at {url}/ in a browser (the lap runs at the wall clock's pace)", flush=True)
    progress = Progress(f"demo {config.track}")
    try:
        with SocketDriver(url) as driver:
            on_frame = hooks(strip, WallClockPacer() if args.watch else None)
            result = run_scenario(config, driver, progress=progress, on_frame=on_frame)
    except KeyboardInterrupt:  # before the lap began (world building, connecting): nothing was driven
        print("\ndegree of autonomy: none, interrupted before the first lap was finished (0 s driven)")
        return 130
    finally:
        progress.close()
        server.cleanup()
    print()
    print_summary(result, f"speed limit {args.speed_limit:g} km/h (drive_server)")
    print(_server_latency(stats_path))
    write_json(out / "result.json", result.to_dict())
    print(f"\nmap   {write_trajectory_map(result, out / 'map.png')}")
    if strip.frames:
        print(f"strip {strip.write(out / 'strip.jpg')}")
    print(f"json  {out / 'result.json'}")
    if replacing:
        print(f"(replaced an earlier run's files in {out}/; --out DIR keeps them apart)")
    finished = [lap for lap in result.laps if lap.completed]
    if finished:
        print(f"\ndegree of autonomy: {', '.join(f'{lap.eta:.1f} %' for lap in finished)}"
              + (f" ({len(finished)} of {args.laps} laps finished: interrupted)" if result.interrupted else ""))
    else:
        print(f"\ndegree of autonomy: none, interrupted before the first lap was finished "
              f"({result.sim_time_s:.0f} s driven)")
    return 130 if result.interrupted else 0
