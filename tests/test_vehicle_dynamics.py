"""Dynamic single-track model: the physics a car at speed must show (issue 12's targets), and the
interface it shares with the kinematic car (sign convention, limits, determinism, frame-rate independence)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest

from tools.sim.track.road import SURFACE_KINDS
from tools.sim.vehicle.dynamics import DynamicVehicle, brush_lateral_force, make_vehicle
from tools.sim.vehicle.kinematic import GRAVITY_MPS2, Vehicle, VehicleParams, VehicleState, kmh_to_mps

P = VehicleParams()


def _car(speed: float = 0.0, params: VehicleParams = P, friction: float | None = None) -> DynamicVehicle:
    car = DynamicVehicle(VehicleState(0.0, 0.0, 0.0, speed), params)
    if friction is not None:
        car.friction = friction
    return car


def _steady(car: DynamicVehicle, steering: float, speed: float, seconds: float = 12.0) -> VehicleState:
    """Hold a wheel angle and a speed (a proportional cruise control) until the car settles."""
    for _ in range(int(seconds * car.params.physics_hz)):
        car.step(steering, max(-1.0, min(1.0, 2.0 * (speed - car.state.speed))))
    return car.state


def _radius(st: VehicleState) -> float:
    return st.speed / abs(st.yaw_rate)


def test_understeer_path_radius_grows_with_speed():
    steering = 0.08  # 2 degrees of wheel angle: a_y stays well under the grip limit
    delta = steering * math.radians(P.max_steer_deg)
    speeds = [5.0, 10.0, 15.0, 20.0, 25.0]
    radii = [_radius(_steady(_car(v), steering, v)) for v in speeds]
    assert all(b > a * 1.05 for a, b in zip(radii, radii[1:], strict=False)), radii
    # linear-tyre steady state: R = (L + K v^2) / delta with the understeer gradient K = m / L (lr / Cf - lf / Cr)
    L, lf, lr = P.wheelbase_m, P.cg_to_front_axle_m, P.cg_to_rear_axle_m
    K = P.mass_kg / L * (lr / P.cornering_stiffness_front_n_per_rad - lf / P.cornering_stiffness_rear_n_per_rad)
    for v, r in zip(speeds, radii, strict=True):
        linear = math.hypot((L + K * v * v) / delta, lr)  # of the centre of gravity
        if v * v / r < 0.25 * GRAVITY_MPS2:  # the tyres' linear range
            assert r == pytest.approx(linear, rel=0.05), (v, r)
        else:  # beyond it the brush tyre softens: more understeer, never less
            assert linear <= r <= 1.25 * linear, (v, r)


def test_lateral_acceleration_saturates_near_mu_g():
    mu = P.friction("asphalt")
    lat = []
    for steering in (0.1, 0.2, 0.3, 0.5, 0.7, 1.0):
        st = _steady(_car(15.0), steering, 15.0, seconds=8.0)
        lat.append(st.speed * abs(st.yaw_rate))
    assert lat[0] < lat[1] < lat[2]  # linear range
    assert 0.85 * mu * GRAVITY_MPS2 <= max(lat) <= 1.02 * mu * GRAVITY_MPS2, lat
    assert max(lat[3:]) - min(lat[3:]) < 0.1 * mu * GRAVITY_MPS2  # more lock gives no more grip: a plateau
    dirt = P.friction("dirt")
    st = _steady(_car(12.0, friction=dirt), 1.0, 12.0, seconds=8.0)
    assert st.speed * abs(st.yaw_rate) <= 1.02 * dirt * GRAVITY_MPS2  # a slippery surface lowers the limit


@pytest.mark.parametrize("surface", ["asphalt", "dirt"])
def test_braking_from_100_kmh_decelerates_at_about_mu_g(surface):
    mu = P.friction(surface)
    v0 = kmh_to_mps(100.0)
    car = _car(v0, friction=mu)
    frames = 0
    while car.state.speed > 0.0:
        car.step(0.0, -1.0)
        frames += 1
        assert frames < 20 * P.physics_hz
    distance = car.state.x
    assert distance == pytest.approx(v0 * v0 / (2 * mu * GRAVITY_MPS2), rel=0.06)
    assert v0 / (frames / P.physics_hz) == pytest.approx(mu * GRAVITY_MPS2, rel=0.08)
    assert abs(car.state.y) < 1e-9 and car.state.yaw == 0.0  # straight braking stays straight
    for _ in range(60):
        car.step(0.0, -1.0)
    assert car.state.x == distance and car.state.speed == 0.0  # stopped, never reversing


@pytest.mark.parametrize("steering", [0.3, -0.6, 1.0])
def test_walking_speed_is_the_kinematic_bicycle(steering):
    speed = kmh_to_mps(5.0)
    dyn, kin = _car(speed), Vehicle(VehicleState(0.0, 0.0, 0.0, speed), P)
    for _ in range(P.physics_hz):  # the wheel reaches its angle (rate limited) while both roll
        dyn.step(steering, 0.0)
        kin.step(steering, 0.0)
        dyn.with_speed(speed)
        kin.with_speed(speed)
    delta = steering * math.radians(P.max_steer_deg)
    assert dyn.state.steer == pytest.approx(kin.state.steer) == pytest.approx(delta)
    radius = P.wheelbase_m / math.tan(abs(delta))  # of the rear axle, as for the kinematic car
    assert _radius(dyn.state) == pytest.approx(math.hypot(radius, P.cg_to_rear_axle_m), rel=1e-9)  # of the CoG
    assert dyn.state.slip == pytest.approx(math.atan(P.cg_to_rear_axle_m / P.wheelbase_m * math.tan(-delta)))
    side = -1.0 if steering > 0 else 1.0  # + steering turns right: the circle's centre is on the right
    s = dyn.state
    cx, cy = s.x - side * radius * math.sin(s.yaw), s.y + side * radius * math.cos(s.yaw)
    for _ in range(2 * P.physics_hz):
        dyn.step(steering, 0.0)
        dyn.with_speed(speed)
        assert math.hypot(dyn.state.x - cx, dyn.state.y - cy) == pytest.approx(radius, rel=1e-4)


def test_hard_braking_at_full_lock_spins_the_car():
    car = _car(kmh_to_mps(100.0))
    slip = [abs(car.step(1.0, -1.0).slip) for _ in range(90)]
    assert max(slip) > math.radians(45)  # the unloaded rear lets go: a spin, for the referee to see
    gentle = _car(kmh_to_mps(50.0))
    assert max(abs(gentle.step(0.2, 0.0).slip) for _ in range(300)) < math.radians(5)


def test_positive_steering_turns_right_like_unity_and_telemetry_reads_the_wheel():
    car = _car(8.0)
    for _ in range(60):
        car.step(0.5, 0.2)
    assert car.state.yaw < 0 and car.state.y < 0 and car.state.yaw_rate < 0
    assert car.steering_deg == pytest.approx(0.5 * P.max_steer_deg)


def test_steering_rate_and_top_speed_limits():
    car = _car(5.0)
    car.step(3.0, 0.0)
    assert car.state.steer == pytest.approx(math.radians(P.steer_rate_deg_s) / P.physics_hz)
    fast = _car(0.0, replace(P, top_speed_kmh=60.0))
    speeds = [fast.step(0.0, 1.0).speed for _ in range(60 * P.physics_hz)]
    assert max(speeds) <= kmh_to_mps(60.0) + 1e-9 and speeds[-1] == pytest.approx(kmh_to_mps(60.0), rel=0.01)
    assert all(b >= a for a, b in zip(speeds, speeds[1:], strict=False))


def test_integration_rate_does_not_depend_on_the_frame_rate():
    def drive(frame_hz: int) -> VehicleState:
        car = _car(0.0, replace(P, physics_hz=frame_hz))
        per_command = frame_hz // 15  # one command per 15 Hz telemetry frame, whatever the frame rate
        for k in range(15 * 20):
            for _ in range(per_command):
                car.step(math.sin(k / 9.0), 0.8 if k % 60 < 40 else -0.4)
        return car.state

    assert drive(60) == drive(30) == drive(90)  # 180 Hz integration: the same steps, bit for bit


def test_same_commands_give_the_same_trajectory():
    def drive() -> VehicleState:
        car = _car()
        for k in range(1200):
            car.step(math.sin(k / 37.0), 0.9 if k % 200 < 150 else -0.5)
        return car.state

    a, b = drive(), drive()
    assert a == b and a.speed > 0


def test_place_puts_the_body_centre_and_rolls_straight():
    car = _car(20.0)
    for _ in range(60):
        car.step(1.0, 0.5)
    car.place(10.0, -4.0, math.radians(90), speed=5.0)
    assert car.centre == pytest.approx((10.0, -4.0))
    s = car.state
    assert s.steer == 0.0 and s.speed == 5.0 and s.yaw_rate == 0.0 and s.slip == 0.0


def test_brush_tyre_is_linear_at_small_slip_and_saturates():
    c, f = 80_000.0, 7_000.0
    assert brush_lateral_force(0.001, c, f) == pytest.approx(-c * 0.001, rel=0.01)
    assert brush_lateral_force(-0.5, c, f) == f and brush_lateral_force(0.5, c, f) == -f
    t_sl = math.atan(3 * f / c)
    assert brush_lateral_force(t_sl * 0.999, c, f) == pytest.approx(-f, rel=1e-4)  # continuous at full sliding
    assert brush_lateral_force(0.2, c, 0.0) == 0.0


def test_every_surface_kind_has_a_friction_and_dirt_is_slippery():
    table = dict(P.surface_friction)
    assert set(SURFACE_KINDS) <= set(table), "a new surface kind needs its friction in VehicleParams"
    assert P.friction("dirt") < P.friction("bridge") < P.friction("asphalt")
    assert P.friction("no-such-kind") == P.friction("asphalt")


def test_make_vehicle_and_parameter_validation():
    assert isinstance(make_vehicle("kinematic", VehicleState(0, 0, 0)), Vehicle)
    assert isinstance(make_vehicle("dynamic", VehicleState(0, 0, 0)), DynamicVehicle)
    with pytest.raises(ValueError, match="unknown vehicle"):
        make_vehicle("hover", VehicleState(0, 0, 0))
    with pytest.raises(ValueError, match="centre of gravity"):
        VehicleParams(cg_to_front_axle_m=3.0)
    with pytest.raises(ValueError, match="kinematic_below"):
        VehicleParams(kinematic_below_mps=5.0, dynamic_above_mps=4.0)


def test_sim_bench_reports_both_cars(tmp_path):
    """``rbc sim-bench``'s car figures: one line per car model, and the in-process loop (behaviour, not speed)."""
    from tests.conftest import write_stadium
    from tools.bench.vehicle_models import inprocess_loop, physics_step_costs

    lines = physics_step_costs(repeats=1, frames=30)
    assert any(line.strip().startswith("kinematic") for line in lines)
    assert any("dynamic" in line and "integration step" in line for line in lines)
    assert any("CommonRoad" in line for line in lines)  # its cost, or how to install it
    line = inprocess_loop(write_stadium(tmp_path), "dynamic", seconds=1.0)
    assert "frames/s wall" in line and "per CPU-second" in line


def test_the_simulation_gives_the_car_the_surface_it_drives_on(tmp_path):
    import json

    from protocol import SteerCommand
    from tests.conftest import write_stadium
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.simulation import Simulation

    def braking_distance(surface: str) -> float:
        path = tmp_path / f"{surface}.json"
        data = json.loads(Path(write_stadium(tmp_path)).read_text())
        data["surfaces"] = [{"from_s": 0.0, "to_s": 500.0, "kind": surface}]
        path.write_text(json.dumps(data))
        sim = Simulation(ScenarioConfig(track=str(path), vehicle="dynamic"), render=False)
        while sim.vehicle.state.speed < kmh_to_mps(60.0):
            sim.advance(1, SteerCommand(0.0, 1.0))
        start = sim.progress
        while sim.vehicle.state.speed > 0.0:
            sim.advance(1, SteerCommand(0.0, -1.0))
        assert not sim.laps and not sim.scorer.interventions
        return sim.progress - start

    asphalt, dirt = braking_distance("asphalt"), braking_distance("dirt")
    assert dirt / asphalt == pytest.approx(P.friction("asphalt") / P.friction("dirt"), rel=0.1)


def test_telemetry_reports_the_wheel_angle_and_speed_of_the_dynamic_car():
    from protocol import SteerCommand
    from tools.sim.driving.scenario import ScenarioConfig
    from tools.sim.driving.simulation import Simulation

    sim = Simulation(ScenarioConfig(track="lake", vehicle="dynamic", speed_unit="kmh"), render=False)
    sim.advance(240, SteerCommand(0.3, 1.0))
    st, payload = sim.vehicle.state, sim.telemetry("")
    assert float(payload["steering_angle"]) == pytest.approx(0.3 * P.max_steer_deg, abs=1e-4)  # + = right
    assert float(payload["speed"]) == pytest.approx(st.speed * 3.6, abs=1e-4) and st.speed > 5.0
    assert float(payload["throttle"]) == 1.0
