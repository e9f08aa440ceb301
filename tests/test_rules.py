"""Scoring rules: eta arithmetic, each intervention cause, the reset after it, lap bookkeeping."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest

from protocol import SteerCommand
from tests.conftest import write_stadium
from tools.sim.driving.autopilot import AutopilotParams
from tools.sim.driving.drivers import AutopilotDriver, Frame, LocalDriver, Scene
from tools.sim.driving.rules import DEFAULT_RULES, Cause, Referee, Rules, angle_diff, body_hits, degree_of_autonomy
from tools.sim.driving.scenario import ScenarioConfig
from tools.sim.driving.session import run_scenario
from tools.sim.driving.simulation import Simulation
from tools.sim.vehicle.kinematic import kmh_to_mps, mps_to_kmh


def stadium(tmp_path, lanes: int = 1, road_width: float = 8.0, straight: float = 150.0, radius: float = 40.0) -> str:
    """A stadium track file: two straights (the first going east) joined by two half circles."""
    return write_stadium(tmp_path, lanes, road_width, straight, radius)


class Scripted(LocalDriver):
    """A driver that applies ``policy(truth)`` (or a fixed command)."""

    name = "scripted"

    def __init__(self, policy: Callable[[Frame], SteerCommand] | SteerCommand) -> None:
        super().__init__()
        self.policy = policy

    def steer(self, frame: Frame) -> SteerCommand:
        return self.policy(frame) if callable(self.policy) else self.policy


def _run(config: ScenarioConfig, driver, rules: Rules = DEFAULT_RULES):
    return run_scenario(config, driver, rules=rules, render=False)


# --------------------------------------------------------------------------------------------- arithmetic


@pytest.mark.parametrize(("n", "t", "eta", "clamped"), [
    (0, 120.0, 100.0, False),
    (1, 60.0, 90.0, False),
    (3, 120.0, 85.0, False),
    (10, 60.0, 0.0, False),  # exactly zero is not clamped
    (11, 60.0, 0.0, True),
])
def test_degree_of_autonomy_is_eq_1_and_2(n, t, eta, clamped):
    assert degree_of_autonomy(n, t) == (pytest.approx(eta), clamped)


def test_seconds_per_intervention_is_a_rule():
    assert degree_of_autonomy(1, 100.0, Rules(seconds_per_intervention=10.0))[0] == pytest.approx(90.0)
    assert Rules().to_dict()["seconds_per_intervention"] == 6.0
    with pytest.raises(AttributeError):
        Rules().stuck_time_s = 1.0  # frozen: a run's rules cannot drift


def test_angle_diff_wraps():
    assert angle_diff(math.radians(179), math.radians(-179)) == pytest.approx(math.radians(-2))


def test_body_hits_uses_the_car_rectangle():
    cones = np.array([[2.45, 0.0], [0.0, 1.1], [0.0, 1.2], [-3.0, 0.0]])
    hit = body_hits(0.0, 0.0, 0.0, 4.6, 1.9, cones, 0.2)
    assert hit.tolist() == [0, 1]  # 0.15 m beyond the bumper, 0.15 m beside the door
    hit = body_hits(0.0, 0.0, 0.0, 4.6, 1.9, cones, 0.14)
    assert hit.tolist() == []


# ------------------------------------------------------------------------------------------ referee unit


def _referee(direction: int = 1, cones=None) -> Referee:
    return Referee(Rules(), 8.0, direction, np.zeros((0, 2)) if cones is None else np.asarray(cones), 4.6, 1.9)


def test_off_road_is_the_car_centre_beyond_the_edge_plus_margin():
    ref = _referee()
    assert ref.check(0.01, 0, 0, 0.0, 5.0, cte=4.49, track_heading=0.0) is None
    assert ref.check(0.01, 0, 0, 0.0, 5.0, cte=-4.51, track_heading=0.0) is Cause.OFF_ROAD


def test_cone_contact_is_an_intervention():
    ref = _referee(cones=[[10.0, 0.0]])
    assert ref.check(0.01, 5.0, 0.0, 0.0, 5.0, 0.0, 0.0) is None
    assert ref.check(0.01, 7.6, 0.0, 0.0, 5.0, 0.0, 0.0) is Cause.CONE


def test_standing_still_for_five_seconds_is_stuck():
    ref = _referee()
    dt = 1 / 60
    causes = [ref.check(dt, 0, 0, 0.0, kmh_to_mps(0.5), 0.0, 0.0) for _ in range(299)]
    assert causes == [None] * 299
    assert ref.check(dt, 0, 0, 0.0, 0.0, 0.0, 0.0) is Cause.STUCK
    ref.reset_timers()
    ref.check(dt, 0, 0, 0.0, 0.0, 0.0, 0.0)
    assert ref.check(dt, 0, 0, 0.0, 5.0, 0.0, 0.0) is None  # moving again resets the clock
    assert ref.still_s == 0.0


@pytest.mark.parametrize("direction", [1, -1])
def test_wrong_way_is_judged_against_the_lap_direction(direction):
    ref = _referee(direction)
    lap_heading = 0.0 if direction > 0 else math.pi
    wrong = lap_heading + math.radians(120)
    dt = 0.1
    assert all(ref.check(dt, 0, 0, lap_heading + math.radians(90), 5.0, 0.0, 0.0) is None for _ in range(50))
    assert [ref.check(dt, 0, 0, wrong, 5.0, 0.0, 0.0) for _ in range(19)] == [None] * 19
    assert ref.check(dt, 0, 0, wrong, 5.0, 0.0, 0.0) is Cause.WRONG_WAY


# ------------------------------------------------------------------------------------- in the simulator


def test_off_road_intervention_resets_the_car_onto_the_line_further_on(tmp_path):
    rules = Rules()
    sim = Simulation(ScenarioConfig(track=stadium(tmp_path)), rules, render=False)
    s0 = sim.proj.s
    while not sim.scorer.interventions:
        sim.advance(1, SteerCommand(0.3, 0.5))  # circles to the right, off the road
    iv = sim.scorer.interventions[0]
    assert iv.cause is Cause.OFF_ROAD
    assert abs(iv.s - s0) < 30 and iv.t == pytest.approx(sim.t)
    # a person put it back: on the centre line, aligned with the lap, rolling, wheels straight
    assert sim.proj.cte == pytest.approx(0.0, abs=1e-6)
    assert angle_diff(sim.vehicle.state.yaw, sim.proj.heading_rad) == pytest.approx(0.0, abs=1e-9)
    assert mps_to_kmh(sim.vehicle.state.speed) == pytest.approx(rules.reset_speed_kmh)
    assert sim.vehicle.state.steer == 0.0
    assert (sim.proj.s - iv.s) % sim.track.length == pytest.approx(rules.reset_ahead_m, abs=0.6)


def test_stuck_car_is_reset_and_counted_each_time(tmp_path):
    result = _run(ScenarioConfig(track=stadium(tmp_path), max_lap_time_s=17.0), Scripted(SteerCommand(0.0, -1.0)))
    lap = result.laps[0]
    assert not lap.completed
    assert [i.cause for i in lap.interventions] == [Cause.STUCK] * 3
    times = [i.t for i in lap.interventions]
    assert times[0] == pytest.approx(5.0, abs=0.1)  # standing at the spawn from t = 0
    assert 5.0 < times[1] - times[0] < 6.5  # rolled at 15 km/h after the reset, braked, stood 5 s


def test_driving_against_the_lap_is_wrong_way(tmp_path):
    config = ScenarioConfig(track=stadium(tmp_path), yaw_offset_deg=180.0, max_lap_time_s=4.0)
    result = _run(config, Scripted(SteerCommand(0.0, 0.3)))
    causes = [i.cause for i in result.laps[0].interventions]
    assert causes and causes[0] is Cause.WRONG_WAY
    assert result.laps[0].interventions[0].t == pytest.approx(2.0, abs=0.5)


def test_reversed_spawn_makes_the_default_direction_wrong(tmp_path):
    track = stadium(tmp_path)
    ok = _run(ScenarioConfig(track=track, reverse=True, max_lap_time_s=4.0), Scripted(SteerCommand(0.0, 0.3)))
    assert not ok.laps[0].interventions  # driving the reversed lap is right
    assert ok.laps[0].distance_m > 0
    bad = _run(ScenarioConfig(track=track, reverse=True, yaw_offset_deg=180, max_lap_time_s=4.0),
               Scripted(SteerCommand(0.0, 0.3)))
    assert [i.cause for i in bad.laps[0].interventions][:1] == [Cause.WRONG_WAY]


def test_cone_hits_are_interventions_and_collisions(tmp_path):
    class ConeSeeker(AutopilotDriver):
        def start(self, scene: Scene) -> None:  # an autopilot that aims AT the cones
            super().start(scene)
            from tools.sim.driving.autopilot import Autopilot

            params = replace(AutopilotParams(), cone_clearance_m=0.0, cone_hold_m=8.0)
            self.autopilot = Autopilot(scene.track, scene.direction, scene.cones, params, scene.vehicle, seed=0)

    result = _run(ScenarioConfig(track=stadium(tmp_path), cones=4, cone_seed=3), ConeSeeker())
    lap = result.laps[0]
    assert lap.completed  # interventions do not end the lap
    assert lap.collisions == 4
    assert [i.cause for i in lap.interventions] == [Cause.CONE] * 4
    assert lap.eta == pytest.approx((1 - 4 * 6.0 / lap.lap_time_s) * 100)
    for iv in lap.interventions:  # each one near a different cone
        assert np.min(np.hypot(*(result.cones - (iv.x, iv.y)).T)) < 3.5


def test_lane_departures_are_counted_but_only_leaving_the_road_intervenes(tmp_path):
    config = ScenarioConfig(track=stadium(tmp_path, lanes=2), max_lap_time_s=20.0)
    result = _run(config, Scripted(SteerCommand(-0.02, 0.3)))  # drifts left across the centre line
    lap = result.laps[0]
    assert lap.lane_departures >= 1
    assert {i.cause for i in lap.interventions} <= {Cause.OFF_ROAD}


def test_autopilot_laps_the_test_track_in_both_directions(tmp_path):
    for reverse in (False, True):
        result = _run(ScenarioConfig(track=stadium(tmp_path), reverse=reverse), AutopilotDriver(seed=1))
        lap = result.laps[0]
        assert lap.completed and lap.n_interventions == 0 and lap.eta == 100.0
        assert lap.distance_m == pytest.approx(result.track_length_m, abs=1.0)
        assert lap.cte_max_m < 1.0


# ------------------------------------------------------------------------------------- spinning out


def test_sliding_sideways_for_a_quarter_second_is_a_spin_out():
    ref = _referee()
    dt = 1 / 60
    over = math.radians(DEFAULT_RULES.spin_out_slip_deg + 5)
    assert ref.check(dt, 0, 0, 0.0, 20.0, 0.0, 0.0, slip=math.radians(25)) is None  # hard cornering is fine
    causes = [ref.check(dt, 0, 0, 0.0, 20.0, 0.0, 0.0, slip=-over) for _ in range(15)]
    assert causes == [None] * 14 + [Cause.SPIN_OUT]  # 15 frames = 0.25 s
    ref.reset_timers()
    assert [ref.check(dt, 0, 0, 0.0, 0.1, 0.0, 0.0, slip=over) for _ in range(30)] == [None] * 30  # at rest


def test_the_dynamic_car_spins_out_under_full_lock_and_full_brake_at_speed(tmp_path):
    wide = stadium(tmp_path, road_width=30.0, straight=500.0, radius=120.0)

    def policy() -> Callable[[Frame], SteerCommand]:
        """Flat out down the straight; past 90 km/h yank the wheel to full lock and brake, and keep them there."""
        yanked = []

        def command(frame: Frame) -> SteerCommand:
            if yanked or frame.truth.speed > kmh_to_mps(90.0):
                yanked.append(frame.t)
                return SteerCommand(1.0, -1.0)
            return SteerCommand(0.0, 1.0)
        return command

    config = ScenarioConfig(track=wide, vehicle="dynamic", max_lap_time_s=15.0)
    lap = _run(config, Scripted(policy())).laps[0]
    assert lap.interventions and lap.interventions[0].cause is Cause.SPIN_OUT
    kinematic = _run(replace(config, vehicle="kinematic"), Scripted(policy())).laps[0]  # follows its arc, stops
    assert Cause.SPIN_OUT not in {i.cause for i in kinematic.interventions}


def test_autopilot_laps_the_test_track_with_the_dynamic_car(tmp_path):
    for reverse in (False, True):
        config = ScenarioConfig(track=stadium(tmp_path, radius=25.0), reverse=reverse, vehicle="dynamic")
        lap = _run(config, AutopilotDriver(seed=1)).laps[0]
        assert lap.completed and lap.n_interventions == 0 and lap.eta == 100.0
        assert lap.cte_max_m < 1.0
