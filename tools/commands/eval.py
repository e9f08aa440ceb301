"""``rbc eval``: the paper's robustness experiments for one model (Table 9 layout)."""

from __future__ import annotations

import argparse
import logging
import os
import time
from datetime import UTC, datetime
from pathlib import Path

from drive_server.serving.model import SteeringModel
from protocol.runrecords import code_version, file_sha256, write_text
from tools.arguments import add_camera_argument, add_monitor_argument, add_vehicle_argument
from tools.console import RunProgress
from tools.errors import CommandError
from tools.evaluate.cluster import BACKENDS, make_runner
from tools.evaluate.evalrecord import RESULTS, EvalRecord
from tools.evaluate.experiments import (
    AUTONOMY_RULE,
    BEHAVIORS,
    DEFAULT_UNSEEN_WORLDS,
    EXPERIMENTS,
    PAPER_EXPERIMENTS,
    SETUPS,
)
from tools.evaluate.journal import driver_identity, prepare_journal
from tools.evaluate.report import format_cell, plot_experiments, table9
from tools.evaluate.runner import DriverSpec, spec_dict
from tools.evaluate.suite import SuiteConfig, max_runs, run_suite
from tools.sim.driving.model_rig import resolve_rig
from tools.sim.track.files import get_track
from tools.sim.worldgen import world_seed_range

log = logging.getLogger("rbc.eval")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", type=Path, help="ONNX model (default: the bundled model of --behavior)")
    d = SuiteConfig  # the defaults, defined once
    p.add_argument("--behavior", choices=BEHAVIORS, default=d.behavior,
                   help="decides the track (lake / mountain / lake with 20 cones) and the experiments")
    p.add_argument("--server", help="drive through a running drive_server at this URL instead of in-process "
                                    "(the speed-limit experiment is then skipped: the limit is the server's)")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="parallel simulator processes (with --backend ray and --address: the cluster's CPUs)")
    p.add_argument("--backend", choices=BACKENDS, default="local",
                   help="local: a process pool on this machine; ray: one Ray task per run (pip extra: cluster)")
    p.add_argument("--address", help="with --backend ray: the cluster to join (auto, or HOST:6379 of "
                                     "`ray start --head`); default: a private Ray instance on this machine")
    p.add_argument("--seeds", type=int, default=d.seeds,
                   help="seeds per eta experiment, mean ± std (default %(default)s)")
    p.add_argument("--seed", type=int, default=d.base_seed, help="first seed (default %(default)s)")
    p.add_argument("--laps", type=int, default=d.laps, help="laps per run (default %(default)s)")
    p.add_argument("--experiments", nargs="+", choices=[e.key for e in EXPERIMENTS] + ["all"],
                   default=list(PAPER_EXPERIMENTS), metavar="EXPERIMENT",
                   help="which experiments: " + ", ".join(e.key for e in EXPERIMENTS) + ", or all "
                        "(default: the paper's eight; unseen_worlds, beyond the paper, only when named)")
    p.add_argument("--worlds", type=int, default=DEFAULT_UNSEEN_WORLDS, metavar="K",
                   help="unseen_worlds: generated evaluation worlds, one run each at --seed (default %(default)s)")
    p.add_argument("--world-seed", type=int, default=None, metavar="S",
                   help="unseen_worlds: first world seed, in the evaluation range "
                        f"{world_seed_range('eval').start}-{world_seed_range('eval').stop - 1} (default: its start)")
    p.add_argument("--world-config", default=None, metavar="JSON",
                   help="unseen_worlds: generator settings, a JSON object of WorldGenConfig fields or a file "
                        "holding one (default: the documented distribution)")
    p.add_argument("--track", help="override the behavior's track (name, world:SEED or JSON file)")
    p.add_argument("--speed-limit", type=float, default=d.speed_limit_kmh,
                   help="km/h for every experiment but the speed one (default %(default)s)")
    add_vehicle_argument(p, d.vehicle)
    add_camera_argument(p, None)
    add_monitor_argument(p, "every run (in-process, as rbc sim --monitor; its figures in each run and row)")
    p.add_argument("--out", type=Path, required=True, help=f"output folder ({RESULTS}, table9.md, plots)")
    p.add_argument("--resume", action="store_true",
                   help="reuse the finished runs journaled in --out by an earlier, interrupted evaluation "
                        "of the same model (runs.jsonl); only the missing runs are driven")


def _model_path(args: argparse.Namespace) -> Path:
    if args.model:
        return args.model
    from drive_server.serving.models_dir import bundled_model_path

    return bundled_model_path(args.behavior)


def _worlds(args: argparse.Namespace, out: Path) -> dict:
    """Generate the unseen worlds into ``out/worlds`` (on this machine, before any run)."""
    from tools.evaluate.worlds import eval_world_seeds, write_eval_worlds
    from tools.sim.worldgen.config import WorldGenConfig, parse_world_config

    seeds = eval_world_seeds(args.worlds, args.world_seed)
    config = parse_world_config(args.world_config) if args.world_config else WorldGenConfig()
    started = time.perf_counter()
    meta = write_eval_worlds(out, seeds, config, args.resume)
    log.info("unseen worlds %d-%d generated in %s in %.1f s", seeds[0], seeds[-1], out / "worlds",
             time.perf_counter() - started)
    return meta


def _monitor(args: argparse.Namespace, steering: SteeringModel, model: Path) -> dict | None:
    """What results.json says of the monitor every run drives with (None: --monitor off); one line if there is none
    to drive with."""
    if args.monitor == "off":
        return None
    from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
    from tools.evaluate.monitor import monitor_meta

    found = steering.monitor()
    if found is None:
        raise CommandError(f"--monitor {args.monitor}: {model.name} carries no misbehaviour monitor",
                           "attach one with rbc monitor fit, or drop --monitor")
    return monitor_meta(found[0], MonitorPolicy(mode=MonitorMode(args.monitor)))


def _print_monitored(summary: dict, monitor: dict) -> None:
    """The printed table with the monitor's columns: each row's episodes, time in warning and alarm, take-overs
    foreseen at least a second ahead and the median lead of the first warning."""
    from tools.evaluate.monitor import MONITOR_HEADS, MONITOR_LEGEND, monitor_cells

    rows = [(exp.title, format_cell(summary[exp.key]), *monitor_cells(summary[exp.key].get("monitor")))
            for exp in EXPERIMENTS if exp.key in summary]
    heads = ("experiment", "result", *MONITOR_HEADS)
    widths = [max(len(r[k]) for r in [heads, *rows]) for k in range(len(heads))]
    print(f"monitor {monitor['score']} ({monitor['mode']}): warning at {monitor['warn']:.4g}, "
          f"alarm at {monitor['alarm']:.4g}")
    for row in [heads, *rows]:
        print("  " + "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip())
    print(MONITOR_LEGEND)
    failed = sum(summary[key].get("monitor", {}).get("failed", 0) for key in summary)
    if failed:
        print(f"the monitor failed and was switched off in {failed} run(s) (runs[].monitor.failed in {RESULTS})")


def run(args: argparse.Namespace) -> int:
    model = _model_path(args)
    if not model.is_file():
        raise CommandError(f"model file not found: {model}", "pass --model PATH to an .onnx file")
    experiments = tuple(e.key for e in EXPERIMENTS if e.key in args.experiments or "all" in args.experiments)
    if "unseen_worlds" not in experiments and (args.world_seed is not None or args.world_config
                                               or args.worlds != DEFAULT_UNSEEN_WORLDS):
        raise CommandError("--worlds, --world-seed and --world-config belong to the unseen_worlds experiment",
                           "add --experiments unseen_worlds (or all)")
    if args.server and args.monitor != "off":
        raise CommandError(f"--monitor {args.monitor} drives the model's monitor in-process; a drive server runs "
                           "its own", "start drive_server with --monitor, or drop --server")
    if args.server and "speed_limit" in experiments:
        log.warning("--server: skipping the speed-limit experiment (the speed limit belongs to the server)")
        experiments = tuple(e for e in experiments if e != "speed_limit")
    # bad input is an error before any output exists: the track, and the model unless a server drives
    if args.track:
        from tools.sim.worldgen.generate import resolve_track_name

        args.track = resolve_track_name(args.track)  # world:SEED -> its file
    get_track(args.track or SETUPS[args.behavior].track)
    monitor_meta = None if args.server else _monitor(args, SteeringModel(model), model)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    worlds_meta = _worlds(args, out) if "unseen_worlds" in experiments else None
    spec = DriverSpec(model=None if args.server else str(model), server=args.server, monitor=args.monitor)
    model_sha = file_sha256(model)
    journal = out / "runs.jsonl"
    track_file = Path(args.track) if args.track and Path(args.track).is_file() else None  # a name: in the code
    reuse = prepare_journal(out, journal, {"model_sha256": model_sha, "behavior": args.behavior,
                                            "driver": driver_identity(spec),
                                            "track_sha256": file_sha256(track_file) if track_file else None},
                            args.resume)
    cfg = SuiteConfig(behavior=args.behavior, seeds=args.seeds, base_seed=args.seed, laps=args.laps,
                      speed_limit_kmh=args.speed_limit, experiments=experiments, track=args.track,
                      map_dir=str(out / "failures"), vehicle=args.vehicle, camera=resolve_rig(args.camera, model),
                      worlds=tuple(worlds_meta["files"].items()) if worlds_meta else ())
    meta = {"model": str(model), "model_resolved": str(model.resolve()), "model_sha256": model_sha,
            "code_version": code_version(),
            "behavior": args.behavior, "seeds": args.seeds, "base_seed": args.seed, "laps": args.laps,
            "workers": args.workers, "driver": spec_dict(spec), "autonomy_rule": AUTONOMY_RULE,
            "suite": {k: v for k, v in vars(cfg).items()}, "started": datetime.now(UTC).isoformat()}
    if worlds_meta:
        meta["worlds"] = worlds_meta
    if monitor_meta:
        meta["monitor"] = monitor_meta

    bar = RunProgress(max_runs(cfg))
    runner = make_runner(args.backend, spec, args.workers, journal, on_result=bar.record, reuse=reuse,
                         address=args.address)
    meta.update(backend=args.backend, workers=runner.workers)
    started = time.perf_counter()
    summary, interrupted = {}, False
    try:
        summary = run_suite(cfg, runner, runner.workers)
    except KeyboardInterrupt:
        interrupted = True
        log.warning("interrupted: keeping the %d finished runs", len(runner.records))
    except BaseException:  # a full disk under the journal, say: cancel the runs in flight and say so once
        interrupted = True
        log.warning("stopped: the %d finished runs are journaled in %s (continue with the same command plus "
                    "--resume)", len(runner.records), journal)
        raise
    finally:
        runner.close(cancel=interrupted)
        bar.close(finished=not interrupted)
    wall = time.perf_counter() - started
    if monitor_meta:
        from tools.evaluate.monitor import add_monitor_rows

        add_monitor_rows(summary, runner.records)
    meta.update(wall_time_s=round(wall, 1), interrupted=interrupted, runs=len(runner.records),
                resumed_runs=runner.reused, retried=runner.retried)
    written = EvalRecord(out, meta, summary, runner.records).write()
    if interrupted:
        print(f"interrupted after {wall:.0f} s; {len(runner.records)} finished runs in {written} "
              f"(continue with the same command plus --resume)")
        return 130
    write_text(out / "table9.md", table9({args.behavior: summary}))
    plots = plot_experiments(summary, runner.records, out)
    resumed = f" ({runner.reused} reused from the journal)" if runner.reused else ""
    retried = f", {len(runner.retried)} failed attempts retried ({RESULTS} meta.retried)" if runner.retried else ""
    print(f"\nRobustness of {model.name} ({args.behavior}), {len(runner.records)} runs{resumed}, "
          f"{runner.workers} workers ({args.backend}){retried}, wall {wall:.0f} s")
    if monitor_meta:
        _print_monitored(summary, monitor_meta)
    else:
        width = max(len(e.title) for e in EXPERIMENTS)
        for exp in EXPERIMENTS:
            if exp.key in summary:
                print(f"  {exp.title:<{width}}  {format_cell(summary[exp.key])}")
    print(f"\nwrote {written}, {out / 'table9.md'}" + (f", {len(plots)} plots" if plots else ""))
    return 0
