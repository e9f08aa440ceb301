"""``rbc fuzz``: a hostile-client campaign against drive_server, and healthy clients' latency beside it.

Library: :mod:`tools.bench.fuzz` and :mod:`tools.bench.fuzz_campaign` (what is sent and checked).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from protocol.runrecords import write_json
from tools.bench.fuzz import fairness, memory_report, open_fds, rss_mib, settled_fds
from tools.bench.fuzz_campaign import DEFAULT_LOG, campaign
from tools.wire.frames import log_frames, synthetic_frames
from tools.wire.server_process import ServerProcess
from tools.wire.unity_client import UnityWireClient


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--server", default=None, help="fuzz a running server at this URL instead of starting one "
                   "(then RSS and file descriptors are measured only with --pid)")
    p.add_argument("--pid", type=int, default=None, help="process id of the --server, for RSS and fd counts")
    p.add_argument("--model", type=Path, default=None,
                   help="ONNX model of the started server (default: the bundled simplistic.onnx, the model the "
                        "campaign's published figures were measured with)")
    p.add_argument("--server-args", default="", help="extra drive_server arguments, e.g. \"--max-pending 32\"")
    p.add_argument("--telemetries", type=int, default=100_000, help="telemetries of the campaign (default 100,000)")
    p.add_argument("--healthy", type=int, default=8, help="healthy 30 Hz clients in the fairness phase (default 8)")
    p.add_argument("--duration", type=float, default=20.0,
                   help="seconds of each fairness condition, interleaved in 2 s phases (default 20)")
    p.add_argument("--no-nice", action="store_true",
                   help="run the misbehaving clients at normal priority (by default they get only idle CPU, "
                        "standing in for clients on other machines, so they do not take the server's or the "
                        "healthy clients' CPU here)")
    p.add_argument("--seed", type=int, default=0, help="seed of the hostile mix and of the frames")
    p.add_argument("--json", type=Path, default=None, help="also write the figures as JSON here")


def run(args: argparse.Namespace) -> int:
    frames = log_frames(DEFAULT_LOG) if DEFAULT_LOG.is_dir() else synthetic_frames(16, seed=args.seed)
    frames = frames[:16]
    server: ServerProcess | None = None
    pid = args.pid
    if args.server:
        url = args.server
    else:
        from drive_server.serving.models_dir import bundled_model_path

        model = args.model or bundled_model_path("simplistic")
        server = ServerProcess(model, ["--log-every", "0", *args.server_args.split()])
        url = server.start()
        pid = server.pid
    try:
        with UnityWireClient(url) as client:  # what a clean connection answers to each good frame
            reference = [client.exchange(f.payload())[0] for f in frames]
        rss0, fds0 = rss_mib(pid), open_fds(pid)
        print(f"server {url}: RSS {rss0} MiB, {fds0} open fds before the campaign")
        t0 = time.perf_counter()
        tally = campaign(url, frames, reference, args.telemetries, args.seed)
        wall = time.perf_counter() - t0
        alive = server is None or server.running
        rss1, fds1 = rss_mib(pid), settled_fds(pid, fds0)
        print(f"campaign: {tally.sent} telemetries over {tally.connections} connections in {wall:.1f} s "
              f"({tally.sent / wall:.0f}/s); answered {tally.answered}; double or missing answers {tally.mismatched}; "
              f"wrong commands on good frames {tally.wrong_commands}; connections closed on a protocol error "
              f"{tally.closed_on_error}; connections lost {tally.lost}; crashes {0 if alive else 1}")
        if rss0 is not None:
            print(f"server after the campaign: {memory_report(rss1, rss0, fds1, fds0)}")
        nice = not args.no_nice
        alone, beside = fairness(url, frames, reference, args.healthy, args.duration, nice, args.seed)
        print(f"{args.healthy} healthy 30 Hz clients alone: round trip p50 {alone['p50_ms']} ms, p99 "
              f"{alone['p99_ms']} ms, max {alone['max_ms']} ms ({alone['frames']} frames)")
        print(f"{args.healthy} healthy 30 Hz clients beside 2 misbehaving ones{'' if nice else ' (not niced)'}: "
              f"round trip p50 {beside['p50_ms']} ms, p99 {beside['p99_ms']} ms, max {beside['max_ms']} ms "
              f"({beside['frames']} frames; the two conditions interleaved every 2 s)")
        rss2, fds2 = rss_mib(pid), settled_fds(pid, fds0)
        if rss0 is not None:
            print(f"server after everything: {memory_report(rss2, rss0, fds2, fds0)}")
        alive = server is None or server.running
        result = {"url": url, "campaign": {k: v for k, v in vars(tally).items() if k != "lock"} | {
                      "wall_s": round(wall, 1), "crashes": 0 if alive else 1},
                  "rss_mib": {"before": rss0, "after_campaign": rss1, "after_all": rss2},
                  "fds": {"before": fds0, "after_campaign": fds1, "after_all": fds2},
                  "healthy_alone": alone, "healthy_beside_misbehaving": beside, "misbehaving_niced": nice}
        if args.json:
            write_json(args.json, result)
        ok = alive and tally.mismatched == 0 and tally.wrong_commands == 0 and tally.lost == 0
        return 0 if ok else 1
    finally:
        if server is not None:
            server.stop()
            text = server.log()
            tail = [ln for ln in text.splitlines() if "stopped:" in ln]
            if tail:
                print("server:", tail[-1].split("stopped: ", 1)[1])
            print(f"server log: {len(text.encode()):,} bytes, {text.count(chr(10)):,} lines, "
                  f"{text.count('Traceback')} tracebacks")
            server.cleanup()
