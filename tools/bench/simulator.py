"""``rbc sim-bench``: world build time and frames/s of the headless renderer, plus a contact sheet.

Measures what the experiments pay for: building a world (cold, and again for a new light direction),
rendering one camera and all three per step on one core (``cv2.setNumThreads(1)`` by default), the JPEG
encoding a Unity-wire client adds, and writes a sheet of sample frames (lake, bridge, cones, mountain,
light intensity and direction sweeps) to look at. Timings are the best of N runs, as wall-clock and as
CPU-time rates (the latter stays meaningful when other processes share the cores).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from protocol.facts import DEPLOY_SPEED_KMH, JPEG_QUALITY
from tools.bench.vehicle_models import inprocess_loop, physics_step_costs
from tools.sim.pictures.text import draw_text
from tools.sim.render.camera import DEFAULT_RIG
from tools.sim.render.renderer import Renderer
from tools.sim.render.world import Pose, clear_caches, get_world
from tools.sim.track.cones import place_cones
from tools.sim.track.files import load_track
from tools.sim.track.road import Track
from tools.sim.vehicle.kinematic import VEHICLE_KINDS

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SimBenchPlan:
    """What one ``rbc sim-bench`` measures; the command's flags and their defaults are these fields."""

    tracks: tuple[str, ...] = ("lake", "mountain")  # built-in track names, track files or world:SEED
    frames: int = 600  # frames per timing run
    repeats: int = 3  # timing runs; the best is reported
    threads: int = 1  # OpenCV threads (1: per-core numbers)
    camera: str = DEFAULT_RIG
    cones: int = 20  # cones for the lake-with-cones run (0: none)
    seed: int = 1  # cone placement seed
    sheet: Path | None = Path("out/sim_sheet.png")  # the contact sheet of sample frames (None: none)
    lap: bool = True  # the closed-loop lap over the socket
    vehicles: tuple[str, ...] = VEHICLE_KINDS  # car models for the physics, in-process and socket figures


def run_sim_bench(plan: SimBenchPlan) -> None:
    """Every figure of ``rbc sim-bench``, printed as it is measured, and the contact sheet."""
    from tools.sim.worldgen.generate import resolve_track_name

    cv2.setNumThreads(plan.threads)
    print(f"rbc sim-bench: 320x160 RGB, {plan.camera} camera rig, OpenCV threads {plan.threads}, "
          f"best of {plan.repeats} x {plan.frames} frames")
    specs = [resolve_track_name(t) for t in plan.tracks]  # world:SEED -> its file
    tracks = [load_track(t) for t in specs]
    for track in tracks:
        bench_track(track, plan)
    lake = next((t for t in tracks if t.name == "lake"), None)
    if lake is not None and plan.cones:
        bench_track(lake, plan, cones=place_cones(lake, plan.cones, plan.seed), builds=False)
    print("\nphysics per step (best of runs):")
    for line in physics_step_costs(plan.repeats):
        print(line)
    print("in-process closed loop, render + JPEG + physics + referee (autopilot driving, one OpenCV thread):")
    for spec in specs:
        for vehicle in plan.vehicles:
            print(inprocess_loop(spec, vehicle))
    for vehicle in plan.vehicles:
        report = lap_wall_time(tracks, plan, vehicle)
        if report:
            print(report)
    if plan.sheet is not None:
        path = write_sheet(tracks, plan.sheet, plan.cones, plan.seed)
        print(f"contact sheet: {path}")


def driving_poses(track: Track, n: int) -> list[Pose]:
    """``n`` poses spread over one lap, weaving a little around the lane centre like a real driver."""
    lane = -track.road_width / 4 if track.lanes == 2 else 0.0
    poses = []
    for s in np.linspace(0.0, track.length, n, endpoint=False):
        x, y, h = track.point_at(s)
        off = lane + 0.8 * math.sin(s / 37.0)
        yaw = h + 0.06 * math.sin(s / 23.0)
        poses.append(Pose(x - math.sin(h) * off, y + math.cos(h) * off, yaw))
    return poses


def _time_frames(fn, poses: list[Pose], repeats: int) -> tuple[float, float]:
    """(wall, cpu) calls per second of ``fn(pose)`` over ``poses``: the best of ``repeats`` runs each.

    The CPU-time rate counts only the time this process ran, so it stays meaningful on a busy machine.
    """
    for p in poses:  # warm up: first touches of the texture pages, visibility cells, LUTs
        fn(p)
    wall, cpu = [], []
    for _ in range(max(1, repeats)):
        t0, c0 = time.perf_counter(), time.process_time()
        for p in poses:
            fn(p)
        wall.append(len(poses) / (time.perf_counter() - t0))
        cpu.append(len(poses) / max(time.process_time() - c0, 1e-9))
    return max(wall), max(cpu)


def bench_track(track: Track, plan: SimBenchPlan, cones: np.ndarray | None = None, builds: bool = True) -> None:
    label = f"{track.name}" + (f" + {len(cones)} cones" if cones is not None else "")
    if builds:
        clear_caches()
        t0 = time.perf_counter()
        world = get_world(track)
        cold = time.perf_counter() - t0
        t0 = time.perf_counter()
        get_world(track, light_direction_deg=10.0)
        relight = time.perf_counter() - t0
        t0 = time.perf_counter()
        world = get_world(track)
        hit = time.perf_counter() - t0
        g = world.ground
        h, w = g.mips[0].shape[:2]
        print(f"\n{label}: {track.length:.0f} m, ground texture {w}x{h} at {g.res * 100:.1f} cm/texel, "
              f"{len(world.props.trees)} trees, {len(world.props.poles)} poles")
        print(f"  world build: {cold:.2f} s cold, {relight:.2f} s for a new light direction, "
              f"{hit * 1e3:.2f} ms cached")
    else:
        t0 = time.perf_counter()
        world = get_world(track, cones=cones)
        print(f"\n{label}: world build {time.perf_counter() - t0:.2f} s")
    renderer = Renderer(world, rig=plan.camera)
    poses = driving_poses(track, plan.frames)
    best, cpu = _time_frames(lambda p: renderer.render(p, "center"), poses, plan.repeats)
    print(f"  centre camera: {best:6.0f} frames/s wall ({1e3 / best:.2f} ms/frame), {cpu:.0f} frames per CPU-second")
    best3, cpu3 = _time_frames(lambda p: [renderer.render(p, c) for c in ("left", "center", "right")],
                               poses, plan.repeats)
    print(f"  3 cameras:     {best3:6.0f} steps/s = {3 * best3:.0f} frames/s wall, "
          f"{3 * cpu3:.0f} frames per CPU-second")
    if builds:
        dim, dim_cpu = _time_frames(lambda p: renderer.render(p, "center", light_intensity=0.6), poses, plan.repeats)
        jit, jit_cpu = _time_frames(lambda p: renderer.render(p, "center", pitch_deg=0.5, roll_deg=-0.4), poses,
                              plan.repeats)
        print(f"  centre camera, light intensity 0.6: {dim:.0f} frames/s wall ({dim_cpu:.0f}/CPU-s); "
              f"with pitch/roll jitter: {jit:.0f} ({jit_cpu:.0f}/CPU-s)")
        frames = [cv2.cvtColor(renderer.render(p), cv2.COLOR_RGB2BGR) for p in poses[:200]]
        params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]
        t0 = time.perf_counter()
        sizes = [len(cv2.imencode(".jpg", f, params)[1]) for f in frames]
        enc = (time.perf_counter() - t0) / len(frames)
        print(f"  JPEG encode (quality {JPEG_QUALITY}): {enc * 1e3:.2f} ms/frame, "
              f"{np.mean(sizes) / 1024:.1f} KiB/frame")


def lap_wall_time(tracks: list[Track], plan: SimBenchPlan, vehicle: str = "kinematic") -> str | None:
    """Closed loop over the socket: one lock-step lap of lake against a real drive_server, on ONE core.

    This process and the server it starts are pinned to the same CPU (children inherit the
    affinity), so the figure is what a single core sustains: render, JPEG, Unity wire, decode,
    inference, control and physics. Uses the bundled simplistic model (random weights if absent), not
    the default model, so the figure stays comparable with the benchmark's history.
    """
    if not plan.lap or not any(t.name == "lake" for t in tracks):
        return None
    import os
    import tempfile

    from drive_server.serving.models_dir import bundled_model_path
    from tools.sim.driving.drivers import SocketDriver
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.session import run_scenario
    from tools.wire.server_process import ServerProcess

    with tempfile.TemporaryDirectory(prefix="rbc_simbench_") as tmp:
        model = bundled_model_path("simplistic")
        if not model.is_file():
            from tools.bench.onnx_builders import save_model

            model = save_model("shallow", Path(tmp) / "shallow.onnx")
        can_pin = hasattr(os, "sched_setaffinity")
        before = os.sched_getaffinity(0) if can_pin else None
        if before is not None:
            os.sched_setaffinity(0, {min(before)})
        try:
            with ServerProcess(model, ["--log-every", "0"]) as server, SocketDriver(server.url) as driver:
                result = run_scenario(ScenarioConfig(track="lake", speed_limit_kmh=DEPLOY_SPEED_KMH, vehicle=vehicle),
                                      driver)
        finally:
            if before is not None:
                os.sched_setaffinity(0, before)
    lap = result.laps[0] if result.laps else None
    per_frame = result.wall_time_s / max(1, result.frames)
    frames_25 = result.track_length_m / (25 / 3.6) * result.config.control_hz  # a lap at a steady 25 km/h
    return (f"closed-loop lap over the socket ({model.name}, {vehicle} car, {'one core' if can_pin else 'unpinned'}): "
            f"{result.wall_time_s:.1f} s wall for {result.sim_time_s:.0f} s simulated, {result.frames} frames "
            f"({per_frame * 1e3:.2f} ms/frame), eta {lap.eta if lap else 0:.1f} %; "
            f"a 1 km lap at 25 km/h ({frames_25:.0f} frames) projects to {frames_25 * per_frame:.1f} s wall")


# ---------------------------------------------------------------------------------------------- sheet


def _label(img: np.ndarray, text: str) -> np.ndarray:
    out = img.copy()
    draw_text(out, text, (5, 16), px=13, box=True)
    return out


def _pose_at(track: Track, s: float, offset: float = 0.0) -> Pose:
    x, y, h = track.point_at(s)
    return Pose(x - math.sin(h) * offset, y + math.cos(h) * offset, h)


def write_sheet(tracks: list[Track], sheet_path: Path, cones: int = SimBenchPlan.cones,
                seed: int = SimBenchPlan.seed) -> Path:
    """Rows of four labelled frames: each track, the bridge, ``cones`` cones placed by ``seed`` on the lake (0:
    none), light intensity and direction sweeps; written to ``sheet_path``."""
    rows: list[list[np.ndarray]] = []
    by_name = {t.name: t for t in tracks}
    for track in tracks:
        r = Renderer(get_world(track))
        lane = -track.road_width / 4 if track.lanes == 2 else 0.0
        s_list = np.linspace(0, track.length, 9, endpoint=False)[1::2]
        rows.append([_label(r.render(_pose_at(track, s, lane)), f"{track.name} s={s:.0f}") for s in s_list])
        p = _pose_at(track, s_list[1], lane)
        rows.append([_label(r.render(p, cam), f"{track.name} {cam} camera") for cam in ("left", "center", "right")]
                    + [_label(r.render(p, "center", pitch_deg=1.5, roll_deg=-1.5), "pitch +1.5, roll -1.5")])
        bridges = [sf for sf in track.surfaces if sf.kind == "bridge"]
        if bridges:
            b = bridges[0]
            rows.append([_label(r.render(_pose_at(track, b.from_s + d, lane)), f"bridge {d:+.0f} m")
                         for d in (-25.0, -8.0, 10.0, 35.0)])
    lake = by_name.get("lake")
    if lake is not None and cones:
        placed = place_cones(lake, cones, seed)
        r = Renderer(get_world(lake, cones=placed))
        tiles = []
        for k, ahead in enumerate((6.0, 10.0, 16.0, 25.0)):
            proj = lake.project(*placed[3 * k])
            tiles.append(_label(r.render(_pose_at(lake, proj.s - ahead)), f"cone {3 * k}, {ahead:.0f} m ahead"))
        rows.append(tiles)
        r = Renderer(get_world(lake))
        p = _pose_at(lake, 60.0)
        rows.append([_label(r.render(p, light_intensity=v), f"light intensity {v:.1f}") for v in (0.2, 0.6, 1.4, 2.0)])
    mountain = by_name.get("mountain", tracks[-1])
    p = _pose_at(mountain, 210.0, -mountain.road_width / 4 if mountain.lanes == 2 else 0.0)
    rows.append([_label(Renderer(get_world(mountain, d)).render(p), f"light direction {d:+.0f} deg")
                 for d in (-30.0, -10.0, 10.0, 30.0)])
    width = max(len(r) for r in rows)
    blank = np.zeros_like(rows[0][0])
    sheet = np.concatenate([np.concatenate(r + [blank] * (width - len(r)), 1) for r in rows], 0)
    sheet_path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(sheet_path), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    return sheet_path
