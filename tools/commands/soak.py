"""``rbc soak``: drive_server for a long time under a steady mix of clients; what drifted, as JSON and a plot.

Library: :mod:`tools.bench.soak` (the clients, the sampler, the checks) and :mod:`tools.bench.soak_plot`.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import tempfile
from pathlib import Path

from protocol.errors import BadValue
from protocol.runrecords import code_version, file_sha256, write_json
from tools.bench.fuzz_campaign import DEFAULT_LOG
from tools.bench.soak import SampleRow, SoakConfig, SoakResult, check_recording
from tools.wire.frames import log_frames, synthetic_frames

_DEFAULTS = SoakConfig()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=_DEFAULTS.duration_s, metavar="S",
                   help="seconds of the soak (default %(default)s: one hour)")
    p.add_argument("--clients", type=int, default=_DEFAULTS.clients,
                   help="simulators in closed loop, their rates spread over 15-30 Hz (default %(default)s)")
    p.add_argument("--sample", type=float, default=_DEFAULTS.sample_s, metavar="S",
                   help="seconds between samples of RSS, fds and latency (default %(default)s)")
    p.add_argument("--model", type=Path, default=None, help="ONNX model (default: drive_server's own default)")
    p.add_argument("--server-args", default="", help="extra drive_server arguments, e.g. \"--max-pending 32\"")
    p.add_argument("--record-dir", type=Path, default=None,
                   help="where the server records (default: a temporary folder, removed afterwards)")
    p.add_argument("--json", type=Path, default=None, help="write the figures here (and the plot beside it)")
    p.add_argument("--plot", type=Path, default=None, help="the plot (default: the --json path with .png)")


def _verdict(result: SoakResult) -> list[str]:
    """The issue's targets, each as one line with its figure."""
    lines = []
    start, end = result["rss_mib_start"], result["rss_mib_end"]
    growth = None if start is None or end is None else round(end - start, 1)
    p99a, p99b = result["p99_ms_first_minute"], result["p99_ms_last_minute"]
    fds_start, fds_end = result["fds_start"], result["fds_end"]
    drift = None if not p99a or p99b is None else round(100 * (p99b - p99a) / p99a, 1)
    checks = [
        ("every telemetry answered once", result["unanswered"] == 0 and result["double_answered"] == 0,
         f"{result['unanswered']} unanswered, {result['double_answered']} answered twice"),
        ("RSS growth < 20 MiB", growth is not None and growth < 20, f"{growth:+} MiB" if growth is not None else "-"),
        ("fds back to their start", fds_end is not None and fds_start is not None and fds_end <= fds_start,
         f"{result['fds_start']} -> {result['fds_end']}"),
        ("p99 of the last minute within 20 % of the first", drift is not None and drift <= 20,
         f"{p99a} -> {p99b} ms ({drift:+} %)" if drift is not None else "-"),
        ("every recorded row has its image", result["recorded_missing_images"] == 0 and result["recorded_rows"] > 0,
         f"{result['recorded_rows']} rows, {result['recorded_missing_images']} without image"),
    ]
    for name, ok, figure in checks:
        lines.append(f"  {'ok  ' if ok else 'FAIL'} {name}: {figure}")
    return lines


def run(args: argparse.Namespace) -> int:
    from drive_server.serving.models_dir import default_model_path
    from tools.bench.soak import Soak
    from tools.bench.soak_plot import plot_soak
    from tools.wire.server_process import ServerProcess

    config = SoakConfig(duration_s=args.duration, clients=args.clients, sample_s=args.sample)
    version = code_version()  # of the code that runs, not of whatever the checkout holds an hour later
    model = args.model or default_model_path()
    frames = log_frames(DEFAULT_LOG) if DEFAULT_LOG.is_dir() else synthetic_frames(16, seed=config.seed)
    own_dir = args.record_dir is None
    record_dir = Path(tempfile.mkdtemp(prefix="rbc_soak_")) / "rec" if own_dir else args.record_dir
    if not own_dir and record_dir.exists() and any(record_dir.iterdir()):
        raise BadValue(f"--record-dir {record_dir} is not empty (the soak counts the rows it recorded)")
    stats_json = record_dir.parent / f"{record_dir.name}.stats.json"
    server = ServerProcess(model, ["--log-every", "0", "--dashboard", "--record", str(record_dir),
                                   *args.server_args.split()], stats_json=stats_json)
    url = server.start()
    print(f"soak: drive_server {url} (pid {server.pid}, model {Path(model).name}, recording to {record_dir}); "
          f"{config.clients} simulators at {', '.join(f'{r:g}' for r in config.rates_hz())} Hz, a reconnect loop, "
          f"an idle socket, malformed frames every {config.malformed_every_s:g} s, the live view; "
          f"{config.duration_s:g} s")

    def progress(t: float, sample: SampleRow) -> None:
        logging.getLogger("rbc.soak").info("%6.0f / %.0f s  RSS %s MiB  fds %s  p50 %s ms  p99 %s ms  (%d frames)",
                                           t, config.duration_s, sample["rss_mib"], sample["fds"], sample["p50_ms"],
                                           sample["p99_ms"], sample["frames"])

    try:
        result = Soak(url, server.pid, frames, config).run(progress)
    finally:
        code = server.stop(timeout=60)  # the recorder flushes its queue on the way out
        log_text = server.log()
        server.cleanup()
    rows, missing = check_recording(record_dir)
    stats = json.loads(stats_json.read_text()) if stats_json.is_file() else {}
    result.update({"recorded_rows": rows, "recorded_missing_images": missing, "server_exit_code": code,
                   "server_tracebacks": log_text.count("Traceback"), "server_faults": stats.get("faults", {})})
    if own_dir:
        shutil.rmtree(record_dir.parent, ignore_errors=True)
    print(f"telemetries {result['telemetries']:,} (answered {result['answered']:,}; unanswered {result['unanswered']}; "
          f"answered twice {result['double_answered']}; malformed {result['malformed']:,}); reconnects "
          f"{result['reconnects']:,}; idle sessions {result['idle_sessions']}; live-view events "
          f"{result['live_events']:,}; driving clients dropped {result['driving_disconnects']}")
    print(f"server RSS {result['rss_mib_before']} MiB before, {result['rss_mib_start']} at the first minute, "
          f"{result['rss_mib_end']} at the end; fds {result['fds_start']} before the clients, "
          f"{result['fds_running_start']} with them, "
          f"{result['fds_end']} after; round trip p50/p99 {result['p50_ms_first_minute']}/"
          f"{result['p99_ms_first_minute']} ms in the first minute, {result['p50_ms_last_minute']}/"
          f"{result['p99_ms_last_minute']} ms in the last; recorded {rows:,} rows, {missing} without image; "
          f"server exit code {code}, {result['server_tracebacks']} tracebacks")
    print("\n".join(_verdict(result)))
    if args.json is not None:
        write_json(args.json, {"code_version": version, "seed": config.seed, "config": config.__dict__,
                               "model": str(model), "model_sha256": file_sha256(model),
                               "server_args": args.server_args, "result": result})
        print(f"wrote {args.json}")
    plot_path = args.plot or (args.json.with_suffix(".png") if args.json is not None else None)
    if plot_path is not None:
        written = plot_soak(result, plot_path)
        print(f"wrote {written}" if written else "no plot: matplotlib is missing (pip extra: plots)")
    return 0
