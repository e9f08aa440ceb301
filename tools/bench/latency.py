"""``rbc bench``: round-trip latency of drive_server over the Unity wire, with the server's stage timings.

Real JPEG frames (a recorded driving log, cycled) go through ``UnityWireClient`` closed loop, one frame
per reply, so the numbers are what a simulator waits for. Without ``--model`` the networks are built with
random weights (``tools.bench.onnx_builders``; needs the ``onnx`` package, not torch): latency does not depend
on the weights. The server runs as a child process unless ``--server URL`` points at a running one.
"""

from __future__ import annotations

import json
import logging
import multiprocessing as mp
import queue
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from drive_server.observing.monitor_stats import monitor_line
from drive_server.observing.stats import STAGES
from tools.errors import CommandError
from tools.wire.frames import SourceFrame, log_frames, synthetic_frames
from tools.wire.server_process import ServerProcess, ServerStartError
from tools.wire.unity_client import UnityWireClient

if TYPE_CHECKING:
    from multiprocessing.queues import Queue
    from multiprocessing.synchronize import Barrier

    from drive_server.wire.server_config import StatsDocument

log = logging.getLogger("rbc.bench")

DEFAULT_LOG = Path(__file__).resolve().parents[2] / "tests" / "data" / "udacity-sample"


@dataclass(frozen=True)
class LatencyPlan:
    """What one ``rbc bench`` measures; the command's flags and their defaults are these fields."""

    server: str | None = None  # a running server's URL (None: start one per model)
    model: Path | None = None  # an ONNX model (None: ``arch`` built with random weights)
    arch: str = "shallow"  # architecture built without a model; "both": shallow and pilotnet
    frames: int = 2000  # measured frames per client
    warmup: int = 200  # unmeasured frames per client first
    clients: int = 1  # concurrent closed-loop clients, one process each
    log_dir: Path | None = None  # driving log the frames come from (None: DEFAULT_LOG, else synthetic frames)
    threads: int = 1  # ONNX Runtime threads of the started server
    workers: int = 1  # worker processes of the started server
    stock_transport: bool = False  # start the server without transport tuning
    record: Path | None = None  # start the server with --record DIR
    monitor: str | None = None  # the started server's --monitor (None: its own default)
    json_out: Path | None = None  # also write the results as JSON here


_NO_STATS: StatsDocument = {}  # an external server's: none


@dataclass
class BenchResult:
    """One benchmark run (one model, M clients)."""

    label: str
    model: str
    clients: int
    frames_per_client: int
    warmup: int
    round_trip_ms: dict[str, float]
    telemetry_per_s: float
    server: StatsDocument = field(default_factory=lambda: _NO_STATS.copy())  # the server's --stats-json
    workers: int = 1


def load_frames(log_dir: Path | None) -> tuple[list[SourceFrame], str]:
    if log_dir is not None:
        frames = log_frames(log_dir)
        return frames, f"{len(frames)} frames of {log_dir}"
    if DEFAULT_LOG.is_dir():
        frames = log_frames(DEFAULT_LOG)
        return frames, f"{len(frames)} frames of {DEFAULT_LOG.relative_to(DEFAULT_LOG.parents[2])}"
    return synthetic_frames(64), "64 synthetic frames"


class ClientRun(TypedDict, total=False):
    """One client's closed loop (``rtts``, ``start``, ``end``), or the ``error`` that ended it."""

    rtts: np.ndarray
    start: float
    end: float
    error: str


def _closed_loop(url: str, log_dir: Path | None, frames_n: int, warmup: int,
                 barrier: Barrier | None = None) -> ClientRun:
    """One client: warm up, wait for the others, then ``frames_n`` timed exchanges."""
    frames, _ = load_frames(log_dir)
    payloads = [f.payload() for f in frames]
    rtts = np.empty(frames_n)
    with UnityWireClient(url, timeout=30.0) as client:
        for i in range(warmup):
            client.exchange(payloads[i % len(payloads)])
        if barrier is not None:
            barrier.wait()
        start = time.monotonic()
        for i in range(frames_n):
            rtts[i] = client.exchange(payloads[i % len(payloads)])[1]
        end = time.monotonic()
    return {"rtts": rtts, "start": start, "end": end}


def _worker(url: str, log_dir: Path | None, frames_n: int, warmup: int, barrier: Barrier,
            results: Queue[ClientRun]) -> None:
    try:
        results.put(_closed_loop(url, log_dir, frames_n, warmup, barrier))
    except BaseException as exc:  # report, never hang the parent
        barrier.abort()
        results.put({"error": f"{type(exc).__name__}: {exc}"})


def drive(url: str, log_dir: Path | None, clients: int, frames_n: int, warmup: int) -> tuple[np.ndarray, float]:
    """Run ``clients`` closed loops against ``url``; returns all round trips (s) and aggregate telemetry/s."""
    if clients == 1:
        runs = [_closed_loop(url, log_dir, frames_n, warmup)]
    else:
        ctx = mp.get_context("spawn")
        barrier, results = ctx.Barrier(clients), ctx.Queue()
        procs = [ctx.Process(target=_worker, args=(url, log_dir, frames_n, warmup, barrier, results), daemon=True)
                 for _ in range(clients)]
        for proc in procs:
            proc.start()
        runs = []
        while len(runs) < clients:
            try:
                runs.append(results.get(timeout=1.0))
            except queue.Empty:
                if not any(p.is_alive() for p in procs):
                    raise RuntimeError("client processes exited without reporting") from None
        for proc in procs:
            proc.join(timeout=30)
        errors = [r["error"] for r in runs if "error" in r]
        if errors:
            raise RuntimeError(f"{len(errors)} client(s) failed: {errors[0]}")
    rtts = np.concatenate([r["rtts"] for r in runs])
    wall = max(r["end"] for r in runs) - min(r["start"] for r in runs)
    return rtts, len(rtts) / wall


def _percentiles_ms(rtts: np.ndarray) -> dict[str, float]:
    p50, p90, p99 = np.percentile(rtts, [50, 90, 99]) * 1e3
    return {"p50": round(float(p50), 4), "p90": round(float(p90), 4), "p99": round(float(p99), 4),
            "max": round(float(rtts.max() * 1e3), 4), "mean": round(float(rtts.mean() * 1e3), 4)}


def format_table(result: BenchResult) -> str:
    """The human-readable table of one run."""
    rows = [f"{'':24}{'p50':>8}{'p90':>8}{'p99':>8}{'max':>8}  ms"]
    rt = result.round_trip_ms
    rows.append(f"{'round trip (client)':24}{rt['p50']:8.3f}{rt['p90']:8.3f}{rt['p99']:8.3f}{rt['max']:8.3f}")
    stages = result.server.get("total", {}).get("stages_ms", {})
    for stage in STAGES:
        if stage in stages:
            s = stages[stage]
            rows.append(f"{'server ' + stage:24}{s['p50']:8.3f}{s['p90']:8.3f}{s['p99']:8.3f}{s['max']:8.3f}")
    total = result.server.get("total", {})
    monitor = total.get("monitor")
    if monitor is not None and monitor["time_ms"]:
        m = monitor["time_ms"]
        rows.append(f"{'  of which monitor':24}{m['p50']:8.3f}{m['p90']:8.3f}{m['p99']:8.3f}{m['max']:8.3f}")
    if total:
        rows.append(f"server frames {total['frames']} (incl. warm-up), malformed {total['malformed']}")
    if monitor is not None:
        rows.append(monitor_line(monitor))
    rows.append(f"throughput {result.telemetry_per_s:,.0f} telemetry/s "
                f"({result.clients} closed-loop client{'s' if result.clients > 1 else ''})")
    return "\n".join(rows)


def bench_one(plan: LatencyPlan, label: str, model: Path | None) -> BenchResult:
    """One model (None: ``plan.server``'s) measured as ``plan`` says."""
    if plan.server:
        rtts, rate = drive(plan.server, plan.log_dir, plan.clients, plan.frames, plan.warmup)
        return BenchResult(label, "(external server)", plan.clients, plan.frames, plan.warmup,
                           _percentiles_ms(rtts), round(rate, 1))
    assert model is not None
    with tempfile.TemporaryDirectory(prefix="rbc_bench_") as tmp:
        stats_path = Path(tmp) / "stats.json"
        server_args = ["--log-every", "0", "--threads", str(plan.threads), "--workers", str(plan.workers)]
        if plan.stock_transport:
            server_args.append("--stock-transport")
        if plan.record is not None:
            server_args += ["--record", str(plan.record)]
        if plan.monitor is not None:
            server_args += ["--monitor", plan.monitor]
        server = ServerProcess(model, server_args, stats_json=stats_path)
        server.start()
        try:
            rtts, rate = drive(server.url, plan.log_dir, plan.clients, plan.frames, plan.warmup)
        finally:
            server.stop()
        stats: StatsDocument = json.loads(stats_path.read_text()) if stats_path.is_file() else {}
    stats.pop("clients", None)
    return BenchResult(label, str(model), plan.clients, plan.frames, plan.warmup, _percentiles_ms(rtts),
                       round(rate, 1), stats, plan.workers)


def _models(plan: LatencyPlan, folder: Path) -> list[tuple[str, Path | None]]:
    """(label, model) of each run: the external server's, ``plan.model``, or random weights saved in ``folder``."""
    if plan.server:
        return [("external", None)]
    if plan.model is not None:
        return [(plan.model.stem, plan.model)]
    names = ["shallow", "pilotnet"] if plan.arch == "both" else [plan.arch]
    try:
        from tools.bench.onnx_builders import ARCHS, save_model

        return [(f"{n} (random weights, {ARCHS[n].params:,} params)", save_model(n, folder / f"{n}.onnx"))
                for n in names]
    except ModuleNotFoundError as exc:
        raise CommandError("building the benchmark's random-weight model needs the package 'onnx'",
                           'pip install -e ".[train]", or pass --model PATH') from exc


def run_bench(plan: LatencyPlan) -> int:
    """``rbc bench``: each model's table printed, the JSON written; the exit status (1: a run failed)."""
    if plan.clients < 1 or plan.frames < 1 or plan.warmup < 0:
        log.error("--clients and --frames must be >= 1, --warmup >= 0")
        return 2
    _, source = load_frames(plan.log_dir)
    results = []
    with tempfile.TemporaryDirectory(prefix="rbc_bench_models_") as tmp:
        for label, model in _models(plan, Path(tmp)):
            workers = "" if plan.server or plan.workers == 1 else f", server with {plan.workers} workers"
            print(f"\n== {label}: {plan.clients} client(s) x {plan.frames} frames (+{plan.warmup} warm-up), "
                  f"{source}{workers}")
            try:
                result = bench_one(plan, label, model)
            except (ServerStartError, RuntimeError, OSError) as exc:
                log.error("benchmark failed: %s", exc)
                return 1
            print(format_table(result))
            results.append(result)
    if plan.json_out is not None:
        from protocol.runrecords import write_json

        write_json(plan.json_out, {"frames_source": source, "runs": [asdict(r) for r in results]})
        print(f"\nwrote {plan.json_out}")
    return 0
