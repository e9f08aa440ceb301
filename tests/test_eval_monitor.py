"""``rbc eval --monitor off|warn|act``: the model's monitor on every run, its figures per run and per row."""

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from tests.conftest import write_stadium
from tools.errors import CommandError
from tools.evaluate.journal import driver_identity, prepare_journal
from tools.evaluate.monitor import run_monitor, summarize_monitor
from tools.evaluate.runner import DriverSpec, Task, run_task

PRETRAINED = Path(__file__).resolve().parents[1] / "models" / "pretrained"
GENERALIST = PRETRAINED / "generalist.onnx"  # carries MC-dropout (four masked copies) and the frame statistics
HEADS = "% warn/alarm"


def _eval(track: str, out: Path, *extra: str, model: Path = GENERALIST) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "tools.cli", "eval", "--model", str(model), "--track", track,
         "--experiments", "no_variation", "--seeds", "1", "--workers", "1", "--out", str(out), *extra],
        capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def track(tmp_path_factory) -> str:
    return write_stadium(tmp_path_factory.mktemp("track"), straight=30.0, radius=15.0)


def test_warn_adds_the_monitor_columns_and_figures(tmp_path, track):
    out = tmp_path / "warn"
    proc = _eval(track, out, "--monitor", "warn")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert HEADS in proc.stdout and "foreseen ≥1 s" in proc.stdout
    assert "monitor mcdropout+framestats (warn)" in proc.stdout
    results = json.loads((out / "results.json").read_text())
    monitor = results["meta"]["monitor"]
    assert monitor["mode"] == "warn" and monitor["score"] == "mcdropout+framestats"
    assert 0 < monitor["warn"] <= monitor["alarm"]
    [run] = results["runs"]
    assert run["frames"] - 1 <= run["monitor"]["frames_scored"] <= run["frames"]  # every frame steered is scored
    assert run["monitor"]["scored_s"] == pytest.approx(run["sim_time_s"], abs=0.2)
    row = results["summary"]["no_variation"]["monitor"]
    assert row["runs"] == 1 and set(row["episodes"]) == {"warning", "alarm"}
    assert row["takeovers_scored"] == run["monitor"]["takeovers_scored"]


def test_off_prints_and_records_no_monitor(tmp_path, track):
    out = tmp_path / "off"
    proc = _eval(track, out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert HEADS not in proc.stdout and "No variation" in proc.stdout
    results = json.loads((out / "results.json").read_text())
    assert "monitor" not in results["meta"] and "monitor" not in results["summary"]["no_variation"]
    assert all("monitor" not in r for r in results["runs"])


def test_act_drives_a_nominal_run_as_off(track):
    """No warning on a nominal lap, so act never slows the car: the same laps, take-overs and eta as off."""
    scenario = {"track": track, "laps": 1, "seed": 0, "spawn_noise": True}
    task = Task("no_variation", "simplistic", None, 0, scenario)
    off = run_task(DriverSpec(model=str(GENERALIST)), task)
    act = run_task(DriverSpec(model=str(GENERALIST), monitor="act"), task)
    assert "monitor" not in off and act["monitor"]["episodes"] == {"warning": 0, "alarm": 0}
    assert act["laps"] == off["laps"] and act["mean_eta"] == off["mean_eta"]


def test_a_model_without_a_monitor_is_one_line(tmp_path, track):
    out = tmp_path / "none"
    proc = _eval(track, out, "--monitor", "warn", model=PRETRAINED / "simplistic.onnx")
    assert proc.returncode == 2 and not proc.stdout
    assert proc.stderr.strip().count("\n") == 0 and "carries no misbehaviour monitor" in proc.stderr
    assert not out.exists()  # refused before any output


def test_a_server_with_monitor_is_one_line(tmp_path, track):
    proc = _eval(track, tmp_path / "srv", "--monitor", "act", "--server", "http://127.0.0.1:9")
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0 and "--monitor act" in proc.stderr


def test_the_journal_keys_on_the_monitor_mode(tmp_path):
    """A journal of runs driven without the monitor is never reused for --monitor warn (or the other way)."""
    off, warn = (driver_identity(DriverSpec(model="m.onnx", monitor=m)) for m in ("off", "warn"))
    assert off != warn and warn["monitor"] == "warn"
    identity = {"model_sha256": "x", "driver": off}
    prepare_journal(tmp_path, tmp_path / "runs.jsonl", identity, resume=False)
    (tmp_path / "runs.jsonl").write_text("{}\n")
    with pytest.raises(CommandError, match="different driver"):
        prepare_journal(tmp_path, tmp_path / "runs.jsonl", identity | {"driver": warn}, resume=True)
    assert prepare_journal(tmp_path, tmp_path / "runs.jsonl", identity, resume=True) == {}


def _scripted(levels: list[int], takeovers: list[tuple[float, str]], hz: float = 10.0):
    """A driver and a run result as run_task has them, with scripted monitor states."""
    readings = [(k / hz, SimpleNamespace(level=lv)) for k, lv in enumerate(levels)]
    starts = [k for k, lv in enumerate(levels) if lv and (k == 0 or levels[k - 1] != lv)]
    episodes = {"warning": sum(levels[k] == 1 for k in starts), "alarm": sum(levels[k] == 2 for k in starts)}
    monitor = SimpleNamespace(state=SimpleNamespace(episodes=episodes), failed=None)
    lap = SimpleNamespace(interventions=[SimpleNamespace(t=t, cause=c) for t, c in takeovers])
    return SimpleNamespace(monitor=monitor, readings=readings), SimpleNamespace(laps=[lap], sim_time_s=len(levels) / hz)


def test_run_figures_from_scripted_states():
    # 20 s at 10 Hz: warning 10-13 s, alarm 13-14 s, then off the road at 14.5 s; a stuck car at 18 s is no misbehaviour
    levels = [0] * 100 + [1] * 30 + [2] * 10 + [0] * 60
    driver, result = _scripted(levels, [(14.5, "off_road"), (18.0, "stuck")])
    m = run_monitor(driver, result)
    assert m["episodes"] == {"warning": 1, "alarm": 1}
    assert m["time_s"] == pytest.approx({"warning": 3.0, "alarm": 1.0}) and m["scored_s"] == pytest.approx(20.0)
    assert (m["takeovers_scored"], m["foreseen"], m["foreseen_1s"]) == (1, 1, 1)
    assert m["leads_s"] == [4.5] and m["lead_median_s"] == 4.5
    # a second run: a warning only half a second ahead is foreseen, but not in time
    late, late_result = _scripted([0] * 95 + [1] * 5 + [0] * 100, [(10.0, "cone")])
    n = run_monitor(late, late_result)
    assert (n["foreseen"], n["foreseen_1s"], n["leads_s"]) == (1, 0, [0.5])
    row = summarize_monitor([{"monitor": m}, {"monitor": n}, {"laps": []}])
    assert row["runs"] == 2 and row["episodes"] == {"warning": 2, "alarm": 1}
    assert row["time_share"] == pytest.approx({"warning": 3.5 / 40, "alarm": 1 / 40})
    assert (row["takeovers_scored"], row["foreseen_1s"], row["lead_median_s"]) == (2, 1, 2.5)
