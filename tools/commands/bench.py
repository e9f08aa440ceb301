"""``rbc bench``: round-trip latency of drive_server over the Unity wire (library: :mod:`tools.bench.latency`)."""

from __future__ import annotations

import argparse
import logging
import tempfile
from dataclasses import asdict
from pathlib import Path

from tools.arguments import add_monitor_argument
from tools.bench.latency import bench_one, format_table, load_frames
from tools.errors import CommandError
from tools.wire.server_process import ServerStartError

log = logging.getLogger("rbc.bench")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--server", default=None, help="benchmark a running server at this URL instead of starting one")
    p.add_argument("--model", type=Path, default=None, help="ONNX model (default: build --arch with random weights)")
    from models.networks.architectures import ARCHITECTURES  # the layer tables only: no torch, no onnx

    p.add_argument("--arch", choices=(*ARCHITECTURES, "both"), default="shallow",
                   help="architecture to build when no --model is given; both: shallow and pilotnet (default shallow)")
    p.add_argument("--frames", type=int, default=2000, help="measured frames per client (default 2000)")
    p.add_argument("--warmup", type=int, default=200, help="unmeasured frames per client first (default 200)")
    p.add_argument("--clients", type=int, default=1, help="concurrent closed-loop clients, one process each")
    p.add_argument("--log", type=Path, default=None, help="driving-log folder to take frames from "
                   "(default: tests/data/udacity-sample, else synthetic frames)")
    p.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads of the started server")
    p.add_argument("--workers", type=int, default=1, help="worker processes of the started server (default 1)")
    p.add_argument("--stock-transport", action="store_true", help="start the server without transport tuning")
    p.add_argument("--record", type=Path, default=None, metavar="DIR",
                   help="start the server with --record DIR (what recording costs the round trip)")
    add_monitor_argument(p, "the started server's")
    p.add_argument("--json", type=Path, default=None, help="also write the results as JSON here")


def run(args: argparse.Namespace) -> int:
    if args.clients < 1 or args.frames < 1 or args.warmup < 0:
        log.error("--clients and --frames must be >= 1, --warmup >= 0")
        return 2
    frames, source = load_frames(args.log)
    with tempfile.TemporaryDirectory(prefix="rbc_bench_models_") as tmp:
        if args.server:
            models: list[tuple[str, Path | None]] = [("external", None)]
        elif args.model is not None:
            models = [(args.model.stem, args.model)]
        else:
            try:
                from tools.bench.onnx_builders import ARCHS, save_model
            except ModuleNotFoundError as exc:
                raise CommandError("building the benchmark's random-weight model needs the package 'onnx'",
                                   'pip install -e ".[train]", or pass --model PATH') from exc
            names = ["shallow", "pilotnet"] if args.arch == "both" else [args.arch]
            try:
                models = [(f"{n} (random weights, {ARCHS[n].params:,} params)",
                           save_model(n, Path(tmp) / f"{n}.onnx")) for n in names]
            except ModuleNotFoundError as exc:
                raise CommandError("building the benchmark's random-weight model needs the package 'onnx'",
                                   'pip install -e ".[train]", or pass --model PATH') from exc
        results = []
        for label, model in models:
            workers = "" if args.server or args.workers == 1 else f", server with {args.workers} workers"
            print(f"\n== {label}: {args.clients} client(s) x {args.frames} frames (+{args.warmup} warm-up), "
                  f"{source}{workers}")
            try:
                result = bench_one(args, label, model, args.log)
            except (ServerStartError, RuntimeError, OSError) as exc:
                log.error("benchmark failed: %s", exc)
                return 1
            print(format_table(result))
            results.append(result)
    if args.json is not None:
        from protocol.runrecords import write_json

        write_json(args.json, {"frames_source": source, "runs": [asdict(r) for r in results]})
        print(f"\nwrote {args.json}")
    del frames
    return 0
