"""Seeds perturb the spawn only when asked (rbc eval), never seed 0, always reproducibly."""

from tools.sim.driving.scenario import ScenarioConfig
from tools.sim.driving.simulation import Simulation


def pose(**kw):
    s = Simulation(ScenarioConfig(track="lake", **kw), render=False).vehicle.state
    return (s.x, s.y, s.yaw)


def test_seed_zero_and_no_noise_spawn_at_the_nominal_pose():
    nominal = pose()
    assert pose(seed=5) == nominal  # without spawn_noise the seed leaves the spawn alone
    assert pose(seed=0, spawn_noise=True) == nominal


def test_other_seeds_perturb_the_spawn_reproducibly_and_a_little():
    nominal = pose()
    a, b = pose(seed=1, spawn_noise=True), pose(seed=2, spawn_noise=True)
    assert a != nominal and b != nominal and a != b
    assert a == pose(seed=1, spawn_noise=True)
    for p in (a, b):
        assert abs(p[0] - nominal[0]) < 0.6 and abs(p[1] - nominal[1]) < 0.6 and abs(p[2] - nominal[2]) < 0.06
