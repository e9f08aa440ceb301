"""The coupled control law (Eq. 14): Table 7 of the paper, units, clamping, and the server's use of it."""

from __future__ import annotations

import pytest

from drive_server.serving.control import ControlLaw
from drive_server.serving.guard import FallbackPolicy, FrameGuard
from protocol import KMH_PER_MPH, SteerCommand

V_L, DELTA = 25.0, 25.0


@pytest.mark.parametrize("tau", [1.0, 0.6])
@pytest.mark.parametrize(("speed", "steer", "expected"), [
    (0.0, 0.0, "tau"),     # standing still, straight: full throttle tau
    (0.0, DELTA, 0.0),     # standing still, full lock: nothing
    (V_L, 0.0, 0.0),       # at the limit, straight: nothing
    (V_L, DELTA, "-tau"),  # at the limit, full lock: brake with tau
])
def test_table_7(tau, speed, steer, expected):
    law = ControlLaw(speed_limit_kmh=V_L, steer_limit_deg=DELTA, tau=tau)
    want = {"tau": tau, "-tau": -tau}.get(expected, expected)
    assert law.command(steer, speed) == pytest.approx(want)
    assert law.command(-steer, speed) == pytest.approx(want)  # |theta|


def test_output_is_clamped_and_negative_brakes():
    law = ControlLaw()
    assert law.command(0.0, -50.0) == 1.0
    assert law.command(25.0, 100.0) == -1.0
    assert law.command(0.0, 30.0) < 0  # over the limit: brake


def test_theta_and_delta_in_the_same_unit():
    # 12.5 degrees of 25 is half the steering term: at standstill xi = 1 - 0.5
    assert ControlLaw().command(12.5, 0.0) == pytest.approx(0.5)


@pytest.mark.parametrize("kwargs", [{"speed_limit_kmh": 0}, {"steer_limit_deg": -1}, {"tau": 1.5}, {"tau": -0.1}])
def test_invalid_parameters(kwargs):
    with pytest.raises(ValueError):
        ControlLaw(**kwargs)


@pytest.mark.parametrize("kwargs", [{"speed_limit_kmh": float("nan")}, {"speed_limit_kmh": float("inf")},
                                    {"steer_limit_deg": float("nan")}, {"tau": "1"}, {"tau": True}])
def test_a_limit_that_is_no_number_is_refused(kwargs):
    """A NaN speed limit made every throttle NaN (drive_server --speed-limit nan was accepted)."""
    from protocol.errors import BadValue

    with pytest.raises(BadValue):
        ControlLaw(**kwargs)


def test_one_law_nested_in_every_config_with_the_steering_conversion():
    """Issue 51: the law's three numbers were copied into DriveConfig and the environment's config, and each
    caller turned normalised steering into degrees by hand."""
    from dataclasses import fields

    from drive_server.serving.pipeline import DriveConfig

    law = ControlLaw(speed_limit_kmh=30.0, steer_limit_deg=20.0, tau=0.5)
    assert law.steering_deg(0.5) == pytest.approx(10.0) and law.steering_deg(-1.0) == -20.0
    assert DriveConfig(law=law).law is law
    copies = [f.name for f in fields(DriveConfig) if f.name in {g.name for g in fields(ControlLaw)}]
    assert copies == []


def test_pipeline_converts_mph_and_normalised_steering(tmp_path):
    pytest.importorskip("onnx")
    from helpers_server import build_shallow

    from drive_server.serving.model import SteeringModel
    from drive_server.serving.pipeline import DriveConfig, DrivePipeline

    model = SteeringModel(build_shallow(tmp_path / "m.onnx"))
    mph = DrivePipeline(model, DriveConfig(speed_unit="mph"))
    kmh = DrivePipeline(model, DriveConfig(speed_unit="kmh"))
    # full steering (1.0 normalised = 25 deg = delta) at 25 km/h: -tau
    assert mph.control(1.0, V_L / KMH_PER_MPH).throttle == pytest.approx(-1.0)
    assert kmh.control(1.0, V_L).throttle == pytest.approx(-1.0)
    assert kmh.control(0.0, 0.0) == SteerCommand(0.0, 1.0)
    # half lock at standstill: half the steering term
    assert kmh.control(0.5, 0.0).throttle == pytest.approx(0.5)


def test_guard_holds_then_stops():
    guard = FrameGuard(FallbackPolicy(hold_frames=3))
    assert guard.bad() == FallbackPolicy().stop_command  # nothing good yet: stop at once
    good = guard.good(SteerCommand(0.3, 0.4))
    assert [guard.bad() for _ in range(3)] == [good] * 3
    assert guard.bad() == SteerCommand(0.0, -1.0)
    assert guard.good(SteerCommand(0.1, 0.2)) == SteerCommand(0.1, 0.2) and guard.bad_run == 0
    with pytest.raises(ValueError):
        FallbackPolicy(stop_throttle=0.5)
