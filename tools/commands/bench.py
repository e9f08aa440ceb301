"""``rbc bench``: round-trip latency of drive_server over the Unity wire (library: :mod:`tools.bench.latency`, whose
:class:`~tools.bench.latency.LatencyPlan` holds this command's defaults)."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.arguments import add_monitor_argument
from tools.bench.latency import LatencyPlan, run_bench

PLAN = LatencyPlan()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--server", default=PLAN.server,
                   help="benchmark a running server at this URL instead of starting one")
    p.add_argument("--model", type=Path, default=PLAN.model,
                   help="ONNX model (default: build --arch with random weights)")
    from models.networks.architectures import ARCHITECTURES  # the layer tables only: no torch, no onnx

    p.add_argument("--arch", choices=(*ARCHITECTURES, "both"), default=PLAN.arch,
                   help="architecture to build when no --model is given; both: shallow and pilotnet "
                        "(default %(default)s)")
    p.add_argument("--frames", type=int, default=PLAN.frames, help="measured frames per client (default %(default)s)")
    p.add_argument("--warmup", type=int, default=PLAN.warmup,
                   help="unmeasured frames per client first (default %(default)s)")
    p.add_argument("--clients", type=int, default=PLAN.clients, help="concurrent closed-loop clients, one process each")
    p.add_argument("--log", type=Path, default=PLAN.log_dir, help="driving-log folder to take frames from "
                   "(default: tests/data/udacity-sample, else synthetic frames)")
    p.add_argument("--threads", type=int, default=PLAN.threads, help="ONNX Runtime threads of the started server")
    p.add_argument("--workers", type=int, default=PLAN.workers,
                   help="worker processes of the started server (default %(default)s)")
    p.add_argument("--stock-transport", action="store_true", help="start the server without transport tuning")
    p.add_argument("--record", type=Path, default=PLAN.record, metavar="DIR",
                   help="start the server with --record DIR (what recording costs the round trip)")
    add_monitor_argument(p, "the started server's")
    p.add_argument("--json", type=Path, default=PLAN.json_out, help="also write the results as JSON here")


def run(args: argparse.Namespace) -> int:
    return run_bench(LatencyPlan(
        server=args.server, model=args.model, arch=args.arch, frames=args.frames, warmup=args.warmup,
        clients=args.clients, log_dir=args.log, threads=args.threads, workers=args.workers,
        stock_transport=args.stock_transport, record=args.record, monitor=args.monitor, json_out=args.json))
