"""The monitor benchmark: its scoring rules on scripted traces (slices, undetectable failures, leads, false alarms,
the Poisson bound), and a tiny benchmark end to end on the headless simulator (journal, resume, record)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tools.monitoreval.scoring import RunTrace, ScoringRules, f_beta, poisson_upper, score

RULES = ScoringRules()
HZ = 15


def _trace(name: str, group: str, seconds: float, alarm_spans=(), takeovers=()) -> RunTrace:
    t = np.arange(0, seconds, 1 / HZ)
    level = np.zeros(t.size, dtype=np.uint8)
    for lo, hi in alarm_spans:
        level[(t >= lo) & (t < hi)] = 1
    return RunTrace(name, group, t, level, list(takeovers), seconds)


def test_a_misbehaviour_warned_three_seconds_ahead_is_recalled_at_1_to_3_s_not_at_4():
    run = _trace("p", "perturbed", 60, alarm_spans=[(26.5, 30)], takeovers=[(30.0, "off_road")])
    nominal = _trace("n", "nominal", 3600)
    f = score([run, nominal], RULES)
    assert f.misbehaviours == 1
    assert [f.recall_at[k] for k in "123456"] == [1, 1, 1, 0, 0, 0]
    assert f.lead_recall_at == {"1": 1, "2": 1, "3": 1} and f.lead_median_s == pytest.approx(3.5, abs=0.07)
    assert f.false_windows == 0 and f.false_episodes == 0 and f.precision_at["1"] == 1.0
    assert f.false_per_hour_upper95 == pytest.approx(2.996, abs=0.01)  # -ln(0.05) events in one hour


def test_failures_soon_after_a_reset_are_left_out_and_short_history_is_a_miss_not_a_drop():
    run = _trace("p", "perturbed", 60, takeovers=[(20.0, "off_road"), (22.0, "off_road"), (29.0, "off_road"),
                                                     (40.0, "stuck")])
    f = score([run], RULES)
    # 22 s is 2 s after the take-over at 20 s: not a failure of its own; 29 s has history from 24 s: its 5 and
    # 6 s slices reach before that, so it is undetectable there, and counted as a miss
    assert f.misbehaviours == 2 and f.other_takeovers == {"stuck": 1}
    assert f.undetectable["5"] == 1 and f.undetectable["6"] == 1 and f.recall_at["6"] == 0


def test_false_alarms_on_nominal_driving_are_counted_per_hour_with_a_bound():
    nominal = _trace("n", "nominal", 1800, alarm_spans=[(100, 102), (900, 901)])
    run = _trace("p", "perturbed", 60, alarm_spans=[(28, 30)], takeovers=[(30.0, "cone")])
    f = score([nominal, run], RULES)
    assert f.false_episodes == 2 and f.false_per_hour == pytest.approx(4.0)
    assert f.false_per_hour_upper95 == pytest.approx(poisson_upper(2) * 2)
    assert f.false_windows >= 3 and f.precision_at["1"] == pytest.approx(1 / (1 + f.false_windows))
    assert f.lead_precision == pytest.approx(1 / 3)  # one of three episodes preceded a failure


def test_poisson_bound_and_f_beta():
    assert poisson_upper(0) == pytest.approx(-math.log(0.05), abs=1e-6)
    assert poisson_upper(5) == pytest.approx(10.513, abs=1e-3)  # chi2(0.95, 12) / 2
    assert f_beta(1.0, 1.0, 3.0) == 1.0 and f_beta(0.5, 1.0, 3.0) == pytest.approx(10 * 0.5 / (9 * 0.5 + 1))


def test_runs_are_never_calibration_worlds():
    from tools.monitoreval.bench import EvalPlan
    from tools.monitoreval.runset import NOMINAL_WORLDS, failing_runs, failure_training_runs, nominal_runs

    calibration = set(range(0, 30)) | set(range(200, 230))  # the bundled monitor's training and calibration worlds
    bench = nominal_runs(200) + failing_runs(EvalPlan.per_setting)
    worlds = {int(s.track.split(":")[1]) for s in bench if s.track.startswith("world:")}
    assert not worlds & calibration and set(NOMINAL_WORLDS) & worlds
    # nor the failure predictor's runs: no track in common, and no degraded copy (noise sigma and seed) in common
    train = failure_training_runs(6, 20)
    assert not {s.track for s in bench} & {s.track for s in train}
    noised = {(s.weight_noise, s.seed) for s in bench if s.weight_noise}
    assert (0.7, 200) in noised and not noised & {(s.weight_noise, s.seed) for s in train if s.weight_noise}


def test_the_default_plan_grades_every_axis_and_holds_enough_failing_runs():
    """The graded intensities the misbehaviour count rests on (docs/monitor.md, "4. Measure it"): light up to 12
    with the milder grades kept, weight noise up to 0.7; --per-setting runs of each."""
    from tools.monitoreval.bench import EvalPlan
    from tools.monitoreval.runset import PERTURBATIONS, WEIGHT_NOISE

    plan = EvalPlan(Path("m.onnx"), Path("out"))
    specs = plan.specs()
    settings = {(s.axis, s.intensity) for s in specs if s.group != "nominal"}
    assert {("light", v) for v in (0.12, 0.18, 0.25, 4.0, 6.0, 8.0, 10.0, 12.0)} <= settings
    assert {("weight_noise", v) for v in (0.15, 0.3, 0.5, 0.7)} <= settings
    per = {}
    for s in specs:
        per[(s.axis, s.intensity)] = per.get((s.axis, s.intensity), 0) + 1
    assert all(per[k] == plan.per_setting for k in settings)
    count = sum(len(v) for v in PERTURBATIONS.values()) + len(WEIGHT_NOISE)
    assert len(specs) == plan.nominal + count * plan.per_setting
    assert not any(s.checkpoint for s in specs)  # under-trained checkpoints only when given


@pytest.mark.slow
def test_a_tiny_benchmark_drives_scores_resumes_and_records(tmp_path):
    """A random model with a brightness monitor on a small track: it leaves the road, the benchmark scores it,
    and a second call reads every run from the journal instead of driving it again."""
    from conftest import write_stadium
    from helpers_server import build_shallow
    from test_monitor import _brightness_graph, _with_monitor

    from drive_server.serving.monitor import MonitorSpec
    from tools.monitoreval import runner
    from tools.monitoreval.report import closed_loop, compare, figures, tables
    from tools.monitoreval.runset import RunSpec

    model = _with_monitor(build_shallow(tmp_path / "m.onnx", seed=3), tmp_path / "mon.onnx",
                          MonitorSpec("brightness", -0.6, -0.55, 15), _brightness_graph())
    stadium_track = write_stadium(tmp_path, straight=40.0, radius=20.0)
    specs = [RunSpec("nominal-0", "nominal", "none", 0.0, stadium_track),
             RunSpec("dark-0", "perturbed", "light", 0.2, stadium_track, light_intensity=0.2)]
    calm = MonitorSpec("brightness", 0.4, 0.45, 15)  # the same score, thresholds it never reaches
    shadow = _with_monitor(tmp_path / "m.onnx", tmp_path / "calm.onnx", calm, _brightness_graph())
    out = tmp_path / "eval"
    results = runner.drive_all(specs, model, ("warn", "act"), out, shadows=(shadow,))
    lines = (out / runner.JOURNAL).read_text().splitlines()
    assert len(lines) == 4 and all(json.loads(line)["run"]["t"] for line in lines)
    run = json.loads(lines[0])["run"]
    assert len(run["shadows"]["calm.onnx"]) == len(run["t"]) == len(run["level"])  # every frame scored by both
    calls = []
    monkey = pytest.MonkeyPatch()
    monkey.setattr(runner, "drive", lambda *a: calls.append(a))
    again = runner.drive_all(specs, model, ("warn", "act"), out, shadows=(shadow,))
    monkey.undo()
    assert calls == [] and [r for *_, r in again] == [r for *_, r in results]
    monkey.setattr(runner, "drive", lambda *a: calls.append(a))
    monkey.setattr(runner, "code_digest", lambda *a: "another code")  # the code that drives has changed since
    rescored = runner.drive_all(specs, model, ("warn", "act"), out, shadows=(shadow,), rescore=True)
    monkey.undo()
    assert calls == [] and [r for *_, r in rescored] == [r for *_, r in results]
    monitors = compare(results, RULES, {"calm.onnx": calm}, "brightness")
    assert [m["monitor"] for m in monitors] == ["brightness", "calm.onnx"]
    assert monitors[1]["figures"]["episodes"] == 0 and monitors[0]["figures"]["episodes"] > 0
    record = {"monitor": {"score": "brightness"}, "figures": figures(results, RULES),
              "closed_loop": closed_loop(results), "cost": None, "monitors": monitors}
    text = tables(record)
    assert "ours: brightness" in text and "SelfOracle" in text and "calm.onnx" in text
    warn = {s.name: r for s, m, r in results if m == "warn"}
    assert warn["nominal-0"]["takeovers"], "a random model should leave the road"


def test_a_failure_in_a_nominal_run_counts_and_its_warning_is_no_false_alarm():
    nominal = _trace("n", "nominal", 600, alarm_spans=[(297, 300)], takeovers=[(300.0, "off_road")])
    f = score([nominal], RULES)
    assert f.misbehaviours == 1 and f.recall_at["1"] == 1
    assert f.false_windows == 0 and f.false_episodes == 0


@pytest.mark.slow
def test_rbc_sim_sums_up_the_monitor_and_draws_its_score(tmp_path):
    from conftest import write_stadium
    from helpers_server import build_shallow
    from test_monitor import _brightness_graph, _with_monitor

    from drive_server.serving.monitor import MonitorSpec
    from tools.cli import main

    model = _with_monitor(build_shallow(tmp_path / "m.onnx", seed=3), tmp_path / "mon.onnx",
                          MonitorSpec("brightness", -0.2, 0.5, 15), _brightness_graph())
    track = write_stadium(tmp_path, straight=40.0, radius=20.0)
    plot = tmp_path / "score.png"
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["sim", "--model", str(model), "--track", track, "--max-lap-time", "40", "--monitor", "warn",
                     "--monitor-plot", str(plot)]) == 0
    text = out.getvalue()
    assert "monitor brightness (warn): 1 warning(s), 0 alarm(s)" in text and "foreseen:" in text
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_world_run_loads_the_generated_world(monkeypatch, tmp_path):
    """world:SEED is a generated world's file for the simulator (the first benchmark failed on every world run)."""
    from helpers_server import build_shallow
    from test_monitor import _brightness_graph, _with_monitor

    from drive_server.serving.monitor import MonitorSpec
    from tools.monitoreval import runner
    from tools.monitoreval.runset import RunSpec
    from tools.sim.driving import session
    from tools.sim.worldgen import resolve_track_name

    resolve_track_name("world:300")  # generating a world drives its autopilot through run_scenario: done first
    seen = []

    def fake(config, driver, **_):
        seen.append(config.track)
        raise RuntimeError("stop here")

    monkeypatch.setattr(session, "run_scenario", fake)
    model = _with_monitor(build_shallow(tmp_path / "m.onnx"), tmp_path / "mon.onnx", MonitorSpec("b", 0, 1, 3),
                          _brightness_graph())
    with pytest.raises(RuntimeError, match="stop here"):
        runner.drive(RunSpec("w", "nominal", "none", 0.0, "world:300"), model, "warn")
    assert seen and seen[0].endswith(".json") and "world-300" in seen[0]


def test_the_threshold_sweep_replays_each_monitor_at_lower_thresholds():
    """A monitor whose calibrated threshold is never reached warns at its calibration's p99 instead: the sweep
    replays the stored one-second means (the driving monitor) and raw scores (a shadow) through the state machine."""
    from drive_server.serving.monitor import MonitorSpec
    from tools.monitoreval.report import sweep
    from tools.monitoreval.runset import RunSpec

    t = list(np.arange(0, 60, 1 / HZ))
    high = [0.5 if 26 <= x < 30 else 0.1 for x in t]  # rises 4 s before the take-over at 30 s
    run = {"t": t, "level": "0" * len(t), "mean": high, "takeovers": [[30.0, "off_road"]], "sim_time_s": 60.0,
           "shadows": {"s.onnx": high}}
    spec = RunSpec("p", "perturbed", "light", 0.2, "lake")
    cal = {"nominal_p99": 0.3, "nominal_max": 0.9}
    rows = sweep([(spec, "warn", run)], RULES, {None: ("ae", MonitorSpec("ae", 1.0, 1.0, 15, cal)),
                                                "s.onnx": ("shift", MonitorSpec("shift", 1.0, 1.0, 15, cal))})
    by = {(r["monitor"], r["threshold"].split(" (")[1]): r for r in rows}
    assert by[("ae", "calibrated)")]["r123"] == "0.0 % / 0.0 % / 0.0 %"
    assert by[("ae", "calibration p99)")]["r123"] == "100.0 % / 100.0 % / 100.0 %"
    assert by[("shift", "calibration p99)")]["lead1"] == "100.0 %"  # its window mean crosses 0.3 within 2 s


def _edited(src: Path, dst: Path, **meta: str) -> Path:
    """``src`` with metadata keys set (``rbc_preprocess`` for ``rbc.preprocess``)."""
    import onnx

    proto = onnx.load(str(src))
    have = {m.key: m.value for m in proto.metadata_props} | {k.replace("_", "."): v for k, v in meta.items()}
    del proto.metadata_props[:]
    for key, value in have.items():
        proto.metadata_props.add(key=key, value=value)
    onnx.save(proto, str(dst))
    return dst


@pytest.fixture()
def served_and_checkpoint(tmp_path):
    from helpers_server import build_shallow
    from test_monitor import _brightness_graph, _with_monitor

    from drive_server.serving.monitor import MonitorSpec

    served = _with_monitor(build_shallow(tmp_path / "s.onnx", seed=3), tmp_path / "served.onnx",
                           MonitorSpec("brightness", -0.6, -0.55, 15), _brightness_graph())
    record = json.dumps({"arch": "shallow", "weights": "random", "epochs": 4, "exported_epoch": 1})
    return served, _edited(build_shallow(tmp_path / "raw.onnx", seed=4), tmp_path / "epoch1.onnx", rbc_model=record)


def test_a_checkpoint_that_reads_or_is_served_otherwise_is_refused_in_one_line(served_and_checkpoint, tmp_path,
                                                                                  capsys):
    from models.onnxfiles.mirror_onnx import mirror_average_onnx
    from protocol.errors import BadValue
    from tools.cli import main
    from tools.monitoreval.modelfiles import check_checkpoint
    from tools.sim.driving.model_rig import RIGS, model_rig

    served, good = served_and_checkpoint
    check_checkpoint(served, good)  # another network of the same contract: fine
    contract = json.loads(_read_meta(good)["rbc.preprocess"]) | {"crop_top": 40}
    mirrored = tmp_path / "mirrored.onnx"
    mirror_average_onnx(good, mirrored)
    other_rig = next(r for r in RIGS if r != model_rig(served))
    bad = {"preprocessing": _edited(good, tmp_path / "crop.onnx", rbc_preprocess=json.dumps(contract)),
           "mirror average": mirrored,
           "smoothed": _edited(good, tmp_path / "smooth.onnx", rbc_serving='{"smoothing": 0.5}'),
           "camera": _edited(good, tmp_path / "rig.onnx", rbc_model=json.dumps({"camera_rig": other_rig})),
           "itself": served}
    for words, path in bad.items():
        with pytest.raises(BadValue, match=words) as info:
            check_checkpoint(served, path)
        assert "\n" not in str(info.value)
    assert main(["monitor", "eval", str(served), "--out", str(tmp_path / "eval"), "--undertrained", str(mirrored),
                 "--nominal", "1", "--per-setting", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "checkpoint mirrored.onnx" in err[0] and "mirror average" in err[0]
    assert not (tmp_path / "eval" / "runs.jsonl").exists()  # refused before any run


def _read_meta(path: Path) -> dict[str, str]:
    import onnx

    return {m.key: m.value for m in onnx.load(str(path)).metadata_props}


def test_the_checkpoints_copy_carries_the_served_monitor_and_its_runs_are_keyed_by_its_content(
        served_and_checkpoint, tmp_path, monkeypatch):
    import onnx
    from helpers_server import build_shallow

    from tools.monitoreval import runner
    from tools.monitoreval.runset import undertrained_runs

    served, checkpoint = served_and_checkpoint
    copy = runner.undertrained_model(checkpoint, served, tmp_path / "models")
    meta, served_meta = _read_meta(copy), _read_meta(served)
    assert {k: v for k, v in meta.items() if k.startswith("rbc.monitor")} == \
        {k: v for k, v in served_meta.items() if k.startswith("rbc.monitor")} and "rbc.monitor" in meta
    assert meta["rbc.model"] == _read_meta(checkpoint)["rbc.model"]  # the checkpoint's own record
    assert onnx.load(str(copy)).graph == onnx.load(str(checkpoint)).graph  # its network, not the served one

    driven = []

    def fake(spec, path, mode, shadows=()):
        driven.append(path)
        return {"t": [0.0], "level": "0", "mean": [0.0], "takeovers": [], "sim_time_s": 1.0}

    monkeypatch.setattr(runner, "drive", fake)
    out = tmp_path / "eval"

    def keys() -> list[dict]:
        specs = undertrained_runs([("epoch1", runner.file_digest(checkpoint), 1.0)], 1)
        runner.drive_all(specs, served, ("warn",), out, checkpoints=(checkpoint,))
        return [json.loads(json.loads(line)["key"]) for line in (out / runner.JOURNAL).read_text().splitlines()]

    first = keys()
    assert len(first) == 1 and driven[-1].name.startswith("epoch1-watched-")
    assert first[0]["model"] == runner.file_digest(driven[-1]) != runner.file_digest(checkpoint)
    assert first[0]["spec"]["axis"] == "undertrained" and first[0]["spec"]["group"] == "degraded"
    assert keys() == first and len(driven) == 1  # the same checkpoint: from the journal
    build_shallow(checkpoint, seed=5)  # the same file name, other weights (another epoch)
    second = keys()
    assert len(driven) == 2 and len(second) == 2 and second[1]["model"] != first[0]["model"]


def test_the_record_lists_the_checkpoints_and_scores_them_as_an_axis(served_and_checkpoint, tmp_path, monkeypatch):
    from tools.monitoreval import runner
    from tools.monitoreval.bench import EvalPlan, evaluate

    served, checkpoint = served_and_checkpoint
    t = [round(i / HZ, 3) for i in range(20 * HZ)]

    def fake(spec, path, mode, shadows=()):  # every under-trained run leaves the road at 10 s, warned from 8 s
        fails = spec.axis == "undertrained"
        level = "".join("1" if fails and 8 <= x < 10 else "0" for x in t)
        return {"t": t, "level": level, "mean": [0.0] * len(t), "takeovers": [[10.0, "off_road"]] if fails else [],
                "sim_time_s": 20.0, "eta": 100.0, "completed": True, "lap_time_s": 20.0, "mean_speed_kmh": 20.0,
                "monitor_failed": False, "shadows": {}}

    monkeypatch.setattr(runner, "drive", fake)
    record = evaluate(EvalPlan(served, tmp_path / "eval", nominal=2, per_setting=2, undertrained=(checkpoint,)))
    assert record["undertrained"] == [{"file": "epoch1.onnx", "sha256": runner.file_digest(checkpoint),
                                       "epochs": 1.0}]
    assert record["plan"]["undertrained"] == [str(checkpoint)]
    assert record["figures"]["by_axis"]["undertrained"]["misbehaviours"] == 2
    assert record["figures"]["by_axis"]["undertrained"]["recall_1"] == 1.0
    assert {s.intensity for s in EvalPlan(served, tmp_path, undertrained=(checkpoint,)).specs()
            if s.axis == "undertrained"} == {1.0}  # graded by the epochs it was trained


def test_runs_of_one_setting_on_a_built_in_track_start_from_other_spawns() -> None:
    """Two runs of a setting on lake differ only by their seed: with the nominal spawn they would be the same
    drive, and the benchmark would count each failure several times."""
    from tools.monitoreval.runner import scenario
    from tools.monitoreval.runset import failing_runs

    lake = [s for s in failing_runs(4) if s.track == "lake" and s.axis == "light" and s.intensity == 8.0]
    configs = [scenario(s, "unity") for s in lake]
    assert len(configs) == 2 and all(c.spawn_noise and c.seed != 0 for c in configs)
    assert configs[0].seed != configs[1].seed and configs[0].light_intensity == configs[1].light_intensity
