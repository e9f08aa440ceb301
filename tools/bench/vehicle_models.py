"""What the car models cost: physics per step, the in-process closed loop per frame, and CommonRoad's.

``rbc sim-bench`` prints these so the choice made in :mod:`tools.sim.vehicle.dynamics` (write the single-track
equations here rather than call ``commonroad-vehicle-models``) can be re-checked on any machine: the
CommonRoad figures appear when that package is installed (``pip install -e ".[commonroad]"``).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

from tools.sim.vehicle.kinematic import VEHICLE_KINDS, VehicleParams, VehicleState

log = logging.getLogger(__name__)


def _best_us(fn: Callable[[], None], calls: int, repeats: int) -> float:
    """Microseconds per call of ``fn``: the best of ``repeats`` timing runs of ``calls`` calls."""
    best = math.inf
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t0) / calls)
    return best * 1e6


def physics_step_costs(repeats: int = 3, frames: int = 6000) -> list[str]:
    """Per 60 Hz simulation frame for each car model (weaving, accelerating and braking)."""
    from tools.sim.vehicle.dynamics import make_vehicle

    params = VehicleParams()
    lines = []
    for kind in VEHICLE_KINDS:
        car = make_vehicle(kind, VehicleState(0.0, 0.0, 0.0, 10.0), params)
        k = [0]

        def step(car=car, k=k) -> None:
            k[0] += 1
            car.step(math.sin(k[0] / 50.0), 0.6 if k[0] % 300 < 200 else -0.4)

        us = _best_us(step, frames, repeats)
        per = f" ({us * params.physics_hz / params.dynamics_hz:.1f} us per {params.dynamics_hz} Hz integration step)" \
            if kind == "dynamic" else ""
        lines.append(f"  {kind:9s} car: {us:5.1f} us per {params.physics_hz} Hz frame{per}")
    lines.extend(_commonroad_costs(repeats))
    return lines


def _commonroad_costs(repeats: int) -> list[str]:
    """CommonRoad's ST and STD right-hand sides (BMW 320i parameters) with an explicit Euler step, if installed."""
    try:
        from vehiclemodels.init_std import init_std
        from vehiclemodels.parameters_vehicle2 import parameters_vehicle2
        from vehiclemodels.vehicle_dynamics_st import vehicle_dynamics_st
        from vehiclemodels.vehicle_dynamics_std import vehicle_dynamics_std
    except ImportError:
        return ["  CommonRoad ST/STD: not installed (pip install commonroad-vehicle-models to compare)"]
    p = parameters_vehicle2()
    out = []
    for name, fn, x0 in (("ST ", vehicle_dynamics_st, [0.0, 0.0, 0.02, 8.0, 0.0, 0.0, 0.0]),
                         ("STD", vehicle_dynamics_std, init_std([0.0, 0.0, 0.02, 8.0, 0.0, 0.0, 0.0], p))):
        state = [list(x0)]

        def euler(fn=fn, state=state) -> None:
            x = state[0]
            state[0] = [a + b / 180.0 for a, b in zip(x, fn(list(x), [0.0, 0.3], p), strict=True)]

        us = _best_us(euler, 5000, repeats)
        out.append(f"  CommonRoad {name}: {us:5.1f} us per Euler step (derivative + update)")
    out.extend(_commonroad_physics(p, vehicle_dynamics_st, vehicle_dynamics_std, init_std))
    return out


def _commonroad_physics(p, st, std, init_std) -> list[str]:
    """The two behaviours that rule CommonRoad's models out here (see tools.sim.vehicle.dynamics)."""
    hz = 180
    x = [0.0, 0.0, 0.3, 30.0, 0.0, 0.0, 0.0]  # ST at 30 m/s holding 0.3 rad of wheel angle
    for _ in range(10 * hz):
        x = [a + b / hz for a, b in zip(x, st(list(x), [0.0, 0.0], p), strict=True)]
    lat = x[3] * x[5]
    y = init_std([0.0, 0.0, 0.0, 8.0, 0.0, 0.0, 0.0], p)  # STD rolling at 8 m/s, braking 4 m/s^2 for 2 s
    for k in range(3 * hz):
        y = [a + b / hz for a, b in zip(y, std(list(y), [0.0, -4.0 if k >= hz else 0.0], p), strict=True)]
    return [f"  CommonRoad ST steady state at 30 m/s, 0.3 rad: lateral acceleration {lat:.0f} m/s^2 "
            f"(mu g = {p.tire.p_dy1 * 9.81:.1f}: linear tyres never saturate)",
            f"  CommonRoad STD, explicit Euler at {hz} Hz, braked to rest from 8 m/s: "
            f"speed {y[3]:+.2f} m/s after the stop"]


def inprocess_loop(track: str, vehicle: str, seconds: float = 40.0) -> str:
    """Frames/s of the in-process closed loop: render + JPEG + physics + referee, the autopilot driving.

    No network model: it measures what the simulator itself costs per telemetry frame.
    """
    from tools.sim.driving.drivers import AutopilotDriver
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.session import run_scenario

    config = ScenarioConfig(track=track, vehicle=vehicle, max_lap_time_s=seconds)
    sim_log = logging.getLogger("tools.sim.driving.simulation")
    level = sim_log.level
    sim_log.setLevel(logging.WARNING)  # the lap ends on its time limit, on purpose
    try:
        run_scenario(ScenarioConfig(track=track, vehicle=vehicle, max_lap_time_s=2.0), AutopilotDriver())  # warm up
        c0 = time.process_time()
        result = run_scenario(config, AutopilotDriver())
        cpu = time.process_time() - c0
    finally:
        sim_log.setLevel(level)
    return (f"  {track:8s} {vehicle:9s}: {result.frames / result.wall_time_s:5.0f} frames/s wall, "
            f"{result.frames / max(cpu, 1e-9):5.0f} per CPU-second ({result.frames} frames, "
            f"{result.sim_time_s:.0f} s simulated)")
