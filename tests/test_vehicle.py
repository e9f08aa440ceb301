"""Kinematic bicycle model: geometry, actuator limits, longitudinal model, determinism."""

from __future__ import annotations

import math

import pytest

from protocol import KMH_PER_MPH
from tools.sim.vehicle.kinematic import Vehicle, VehicleParams, VehicleState, kmh_to_mps, mps_to_kmh


def _car(speed: float = 0.0, yaw: float = 0.0, params: VehicleParams | None = None) -> Vehicle:
    return Vehicle(VehicleState(0.0, 0.0, yaw, speed), params)


def test_straight_line_keeps_heading_and_lateral_position():
    car = _car(speed=10.0, yaw=math.radians(30))
    for _ in range(120):
        car.step(0.0, 0.3)
    s = car.state
    assert s.yaw == pytest.approx(math.radians(30), abs=1e-12)
    assert s.y / s.x == pytest.approx(math.tan(math.radians(30)), rel=1e-9)  # still on the 30 degree ray
    assert s.x > 0 and s.speed > 0


@pytest.mark.parametrize("steering", [0.2, 0.6, 1.0, -0.5])
def test_constant_steer_circle_radius_is_wheelbase_over_tan_delta(steering):
    params = VehicleParams()
    car = _car(speed=6.0, params=params)
    for _ in range(params.physics_hz):  # let the wheel reach its angle (rate limited)
        car.step(steering, 0.0)
        car.with_speed(6.0)
    delta = steering * math.radians(params.max_steer_deg)
    assert car.state.steer == pytest.approx(delta, abs=1e-12)
    radius = params.wheelbase_m / math.tan(abs(delta))
    s = car.state
    # positive steering turns right: the centre of the circle is to the right of the rear axle
    side = -1.0 if steering > 0 else 1.0
    cx = s.x + side * radius * -math.sin(s.yaw)
    cy = s.y + side * radius * math.cos(s.yaw)
    for _ in range(3 * params.physics_hz):
        car.step(steering, 0.0)
        car.with_speed(6.0)
        assert math.hypot(car.state.x - cx, car.state.y - cy) == pytest.approx(radius, rel=1e-9)


def test_positive_steering_turns_right_like_unity():
    car = _car(speed=8.0)
    for _ in range(60):
        car.step(0.5, 0.2)
    assert car.state.yaw < 0  # clockwise
    assert car.state.y < 0  # right of the initial heading (east)


def test_steering_is_limited_in_angle_and_rate():
    params = VehicleParams()
    car = _car(speed=5.0, params=params)
    car.step(3.0, 0.0)  # beyond full lock
    assert car.state.steer == pytest.approx(math.radians(params.steer_rate_deg_s) * params.dt)
    for _ in range(params.physics_hz):
        car.step(3.0, 0.0)
    assert car.state.steer == pytest.approx(math.radians(params.max_steer_deg))
    before = car.state.steer
    car.step(-1.0, 0.0)  # full opposite lock: the wheel still moves at the rate limit only
    assert before - car.state.steer == pytest.approx(math.radians(params.steer_rate_deg_s) * params.dt)


def test_full_throttle_reaches_but_never_exceeds_the_top_speed():
    params = VehicleParams(top_speed_kmh=30.19 * KMH_PER_MPH)  # the stock Udacity car
    car = _car(params=params)
    speeds = []
    for _ in range(90 * params.physics_hz):
        speeds.append(car.step(0.0, 1.0).speed)
    assert max(speeds) <= params.top_speed_mps + 1e-12
    assert mps_to_kmh(speeds[-1]) / KMH_PER_MPH == pytest.approx(30.19, rel=0.01)  # the Udacity car's 30 mph
    assert all(b >= a for a, b in zip(speeds, speeds[1:], strict=False))  # monotonic acceleration


def test_coasting_slows_down_and_braking_stops_without_reversing():
    params = VehicleParams()
    car = _car(speed=kmh_to_mps(30.0), params=params)
    car.step(0.0, 0.0)
    assert car.state.speed < kmh_to_mps(30.0)  # drag and rolling resistance
    x0 = car.state.x
    for _ in range(5 * params.physics_hz):
        car.step(0.0, -1.0)
    assert car.state.speed == 0.0
    assert car.state.brake == 1.0 and car.state.throttle == 0.0
    # stopping distance close to v^2 / (2 a) with a >= the brake deceleration (drag helps)
    assert 0 < car.state.x - x0 <= kmh_to_mps(30.0) ** 2 / (2 * params.max_brake_mps2) + 0.5
    x_stop = car.state.x
    for _ in range(60):
        car.step(0.0, -1.0)
    assert car.state.x == x_stop  # no creeping backwards


def test_same_commands_give_the_same_trajectory():
    def drive() -> VehicleState:
        car = _car()
        for k in range(600):
            car.step(math.sin(k / 37.0), 0.6 if k % 90 < 60 else -0.3)
        return car.state

    assert drive() == drive()


def test_place_puts_the_body_centre_and_straightens_the_wheels():
    car = _car(speed=3.0)
    for _ in range(30):
        car.step(1.0, 0.5)
    car.place(10.0, -4.0, math.radians(90), speed=5.0)
    assert car.centre == pytest.approx((10.0, -4.0))
    assert car.state.steer == 0.0 and car.state.speed == 5.0 and car.state.yaw == pytest.approx(math.pi / 2)
