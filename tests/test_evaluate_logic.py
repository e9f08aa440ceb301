"""The evaluation's pure logic: outward range search, seed aggregation, the Table 9 writer."""

import pytest

from tools.evaluate.experiments import EXPERIMENTS, experiment, is_autonomous
from tools.evaluate.report import format_cell, table9
from tools.evaluate.search import ladder, step_outward
from tools.evaluate.suite import summarize_eta


def run(etas, completed=True, interventions=0):
    return {"laps": [{"eta": e, "completed": completed, "interventions": [{}] * interventions} for e in etas]}


def test_ladder_steps_outward_to_the_cap_inclusive():
    assert ladder(1.0, 0.1, 1.5) == [1.1, 1.2, 1.3, 1.4, 1.5]
    assert ladder(0.0, -5.0, -20.0) == [-5.0, -10.0, -15.0, -20.0]
    assert ladder(0.0, 1.0, 0.0) == []
    with pytest.raises(ValueError):
        ladder(0.0, 0.0, 1.0)


@pytest.mark.parametrize("batch", [1, 3, 10])
def test_search_stops_at_first_failure(batch):
    asked = []

    def evaluate(values):
        asked.extend(values)
        return [v < 4 or v == 6 for v in values]  # 6 would pass again: stepping must not reach it as a limit

    res = step_outward(evaluate, 0, 1, 10, batch=batch)
    assert res.limit == 3 and res.first_failure == 4 and not res.hit_cap
    assert [v for v, _ in res.tried] == [1, 2, 3, 4]
    if batch == 1:
        assert asked == [1, 2, 3, 4]  # nothing evaluated past the failure


def test_search_reports_the_cap_and_immediate_failure():
    res = step_outward(lambda vs: [True] * len(vs), 0, -5, -20)
    assert res.hit_cap and res.limit == -20 and res.first_failure is None
    res = step_outward(lambda vs: [False] * len(vs), 0, 1, 5)
    assert res.limit == 0 and res.first_failure == 1  # only the origin (assumed passing) survives


def test_autonomy_is_no_intervention_and_completed():
    assert is_autonomous(run([100.0]))
    assert not is_autonomous(run([95.0], interventions=1))
    assert not is_autonomous(run([100.0], completed=False))
    assert not is_autonomous({"laps": []})


def test_seed_aggregation_mean_and_population_std():
    s = summarize_eta([run([100.0]), run([90.0], interventions=1), run([95.0, 85.0], interventions=1)])
    assert s["mean"] == pytest.approx(93.333333, abs=1e-4)
    assert s["std"] == pytest.approx(4.7140452, abs=1e-4)
    assert s["n"] == 3 and s["autonomous"] == 1


def test_cells_use_the_papers_notation():
    eta = {"measure": "eta", "values": {"None": {"mean": 100.0, "std": 0.0}}}
    assert format_cell(eta) == "η = 100.0 ± 0.0 %"
    cones = {"measure": "eta", "values": {k: {"mean": 100.0, "std": 0.0} for k in ("20", "10", "0")}}
    assert format_cell(cones).startswith("η{20, 10, 0} = 100.0 ± 0.0 / ")
    light = {"measure": "range", "origin": 1.0, "unit": "cd",
             "lower": {"limit": 0.6, "hit_cap": False}, "upper": {"limit": 1.1, "hit_cap": False}}
    assert format_cell(light) == "[-0.4, +0.1] cd"
    yaw = {"measure": "range", "origin": 0.0, "unit": "°",
           "lower": {"limit": -90.0, "hit_cap": True}, "upper": {"limit": 15.0, "hit_cap": False}}
    assert format_cell(yaw) == "[≤-90°, +15°]"
    speed = {"measure": "max", "origin": 30.0, "unit": "km/h", "upper": {"limit": 45.0, "hit_cap": False}}
    assert format_cell(speed) == "45 km/h"
    assert format_cell({**speed, "upper": {"limit": None}}) == "< 30 km/h"
    assert format_cell({"measure": "range", "empty": True, "unit": "°", "origin": 0}).startswith("none")


def test_table9_has_every_experiment_and_the_papers_column():
    text = table9({"collision": {"no_variation": {"measure": "eta", "values": {"None": {"mean": 100.0, "std": 0.0}}}}})
    for exp in EXPERIMENTS:
        assert (exp.title in text) == exp.paper  # beyond the paper: a row only where it was run
    assert "Collision (paper)" in text and "[-55°, +40°]" in text and "n/a" in text


def test_experiment_lookup():
    assert experiment("speed_limit").realtime
    with pytest.raises(KeyError):
        experiment("nope")


def test_plot_points_draw_a_range_from_its_no_variation_run():
    from tools.evaluate.experiments import experiment
    from tools.evaluate.report import plot_points

    def rec(exp, value, seed, eta, ok):
        return {"experiment": exp, "value": value, "seed": seed, "laps": [{"eta": eta}], "autonomous": ok}

    records = [rec("no_variation", None, 1, 100.0, True), rec("no_variation", None, 0, 100.0, True),
               rec("light_intensity", 1.2, 0, 100.0, True), rec("light_intensity", 0.8, 0, 90.0, False)]
    entry = {"measure": "range", "origin": 1.0}
    points = plot_points(experiment("light_intensity"), entry, records)
    assert [(round(x, 6), y, ok) for x, y, ok in points] == [(-0.2, 90.0, False), (0.0, 100.0, True),
                                                              (0.2, 100.0, True)]
    assert plot_points(experiment("orientation"), {"measure": "range", "origin": 0.0}, records) == []


def test_the_car_model_reaches_every_run_of_the_suite():
    from tools.evaluate.suite import SuiteConfig, base_scenario
    from tools.sim.driving.scenario import ScenarioConfig

    assert base_scenario(SuiteConfig())["vehicle"] == ScenarioConfig.vehicle
    scenario = base_scenario(SuiteConfig(vehicle="dynamic"))
    assert scenario["vehicle"] == "dynamic" and ScenarioConfig(**scenario).vehicle == "dynamic"


def test_the_ray_backend_without_ray_says_which_extra_to_install(monkeypatch):
    import sys

    from tools.errors import CommandError
    from tools.evaluate.cluster import import_ray

    monkeypatch.setitem(sys.modules, "ray", None)  # as if the cluster extra were not installed
    with pytest.raises(CommandError) as exc:
        import_ray()
    assert "[cluster]" in exc.value.hint


def test_projection_replays_the_eta_phase_then_the_search_chains():
    from tools.evaluate.projection import project

    runs = [{"experiment": "no_variation", "value": None, "wall_time_s": t} for t in (3.0, 3.0, 2.0)]
    runs += [{"experiment": "orientation", "value": v, "wall_time_s": 1.0} for v in (5.0, 10.0, -5.0)]
    runs += [{"experiment": "speed_limit", "value": v, "wall_time_s": 4.0} for v in (30.0, 35.0)]
    results = {"runs": runs, "summary": {"no_variation": {"measure": "eta"},
                                         "orientation": {"measure": "range", "origin": 0.0},
                                         "speed_limit": {"measure": "max", "origin": 30.0}}}
    one, two, many = (project(results, w) for w in (1, 2, 64))
    assert one.wall_s == 8.0 + 11.0  # every run in a row
    assert (two.eta_phase_s, two.search_phase_s) == (5.0, 9.0)  # the searches start in order: speed waits 1 s
    assert (many.eta_phase_s, many.search_phase_s) == (3.0, 8.0)  # the speed-limit chain: 8 s of runs in a row
