"""One scenario, driven to the end: the simulator's main loop, the driver pipeline and the results.

``run_scenario(config, driver)`` is what ``rbc sim`` and the robustness experiments call. It is
pure (no globals but read-only caches), deterministic per seed in lock-step mode, and cheap to set
up, so many scenarios can run in parallel processes.

Timing model
  Physics runs at ``sim_fps`` (60 Hz) frames. The Unity simulator emits two telemetries when the
  socket opens and then one per reply, so two frames are always in flight (pipeline depth 2): the
  reply to frame k is applied after frame k+1 was already sent, a one-frame command delay. Every
  driver sees exactly this, the socket driver because it really talks to a server that way, the
  in-process drivers because the session queues their frames the same way, so one model gives the
  same lap over the socket and in-process.

  Lock-step (default): each reply advances the physics one control period (``sim_fps /
  control_hz`` frames) with the new command, then the next frame is rendered and sent. As fast as
  the machine allows and bit-for-bit reproducible.

  Real time (``realtime=True``): simulated time is the driver's measured wall time. While the
  simulator waits for a reply the physics keeps running with the previous command for that long
  (rounded to whole frames, at least one); then the new command applies and the next frame is
  rendered at once, as Unity emits telemetry in its reply handler. A slow model therefore steers
  late, as in the real simulator (the paper's speed-limit experiment depends on it). Not
  reproducible run to run, by nature.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from protocol import encode_image
from tools.sim.driving.rules import DEFAULT_RULES, Rules
from tools.sim.driving.scenario import FrameEvent, RunResult, ScenarioConfig
from tools.sim.driving.simulation import Simulation

if TYPE_CHECKING:
    from tools.sim.driving.drivers import Driver

log = logging.getLogger(__name__)

#: Frames in flight between simulator and driver (the Unity simulator's behaviour, see module doc).
PIPELINE_DEPTH = 2

__all__ = ["PIPELINE_DEPTH", "run_scenario"]


def run_scenario(config: ScenarioConfig, driver: Driver, progress: Callable[[float, float], None] | None = None,
                 on_frame: Callable[[FrameEvent], None] | None = None, rules: Rules = DEFAULT_RULES,
                 render: bool = True) -> RunResult:
    """Drive ``config.laps`` laps with ``driver`` (see :mod:`tools.sim.driving.drivers`) and score them.

    ``progress(done_m, total_m)`` is called about once per simulated second; ``on_frame`` gets every
    telemetry frame. Ctrl-C ends the run early with the laps finished so far (``interrupted``).
    ``render=False`` sends frames without an image: only for drivers that use the ground truth (the
    autopilot), e.g. fast tests of the driving rules.
    """
    from tools.sim.driving.drivers import Frame, Scene

    sim = Simulation(config, rules, render=render)
    fps, per_command = config.sim_fps, config.frames_per_command
    total_m = config.laps * sim.track.length
    latencies: list[float] = []
    frames = 0
    interrupted = False
    wall0 = time.perf_counter()

    def send() -> None:
        nonlocal frames
        rgb = sim.render("center", sim.camera_jitter()) if render else None
        payload = sim.telemetry(encode_image(rgb, sim.jpeg_quality) if rgb is not None else "")
        driver.send(Frame(payload=payload, t=sim.t, truth=sim.vehicle.state))
        frames += 1
        if on_frame is not None and rgb is not None:
            on_frame(FrameEvent(sim.t, sim.lap, rgb, sim.vehicle.state, sim.command, sim.last_intervention))

    driver.start(Scene(track=sim.track, cones=sim.cones, direction=sim.direction, seed=config.seed,
                       vehicle=sim.params, control_period_s=per_command / fps))
    next_report = 0.0
    try:
        for _ in range(PIPELINE_DEPTH):
            send()
        command = sim.command
        while not sim.done:
            t0 = time.perf_counter()
            reply = driver.receive()
            waited = time.perf_counter() - t0
            latencies.append(reply.latency_s)
            if config.realtime:
                sim.advance(max(1, round(waited * fps)), command)
                if sim.done:
                    break
            if reply.command is not None:  # None: a 'manual' reply, the previous command stays
                command = reply.command
            sim.command = command
            if not config.realtime:
                sim.advance(per_command, command)
                if sim.done:
                    break
            send()
            if progress is not None and sim.t >= next_report:
                next_report = sim.t + 1.0
                progress(min(total_m, max(0.0, sim.progress)), total_m)
    except KeyboardInterrupt:
        interrupted = True
        log.warning("interrupted at t=%.1f s (lap %d); returning the laps finished so far", sim.t, sim.lap)
    finally:
        driver.stop()
    if progress is not None and not interrupted:
        progress(total_m, total_m)
    lat_ms = np.array(latencies) * 1000.0 if latencies else np.zeros(1)
    return RunResult(
        config=config, rules=rules, driver=getattr(driver, "name", type(driver).__name__), laps=sim.laps,
        wall_time_s=time.perf_counter() - wall0, sim_time_s=sim.t, frames=frames,
        latency_ms_p50=float(np.percentile(lat_ms, 50)), latency_ms_p99=float(np.percentile(lat_ms, 99)),
        track_length_m=sim.track.length, interrupted=interrupted, trace=sim.trace(), cones=sim.cones,
    )
