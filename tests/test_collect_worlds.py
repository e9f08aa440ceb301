"""``rbc collect --worlds``: one Udacity data set over generated worlds, its world record, and its guarantees."""

from __future__ import annotations

import csv
import importlib.util
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

from protocol.datalog import read_log
from protocol.runrecords import file_sha256
from tools.cli import main
from tools.sim.collect.dataset import CollectConfig
from tools.sim.collect.worlds import WorldsConfig, collect_worlds, world_collect_seed, world_light_intensity
from tools.sim.track.files import load_track
from tools.sim.worldgen import WorldGenConfig

ROOT = Path(__file__).resolve().parents[1]
SHORT = WorldGenConfig(min_length_m=200, max_length_m=400, drive_check=False)  # 0.2-0.4 km loops: quick
SHORT_JSON = '{"min_length_m": 200, "max_length_m": 400, "drive_check": false}'
CONFIG = CollectConfig(cameras=3, rate_hz=1.0, seed=3)


def _collect(out: Path, workers: int, **kw):
    return collect_worlds(CONFIG, WorldsConfig(first_seed=10, count=3, generator=SHORT), out, workers=workers, **kw)


def _log(out: Path) -> str:
    return (out / "driving_log.csv").read_text().replace(str(out), "OUT")


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("w1") / "data"
    result = _collect(out, workers=1)
    assert not result.interrupted and [o.seed for o in result.outcomes] == [10, 11, 12]
    return out


def test_the_data_set_reads_back_and_worlds_csv_says_where_every_row_is_from(one_worker):
    out = one_worker
    samples, report = read_log(out)  # the 7-column Udacity log, every row with its three frames
    assert not report.skipped and len(samples) == len((out / "driving_log.csv").read_text().splitlines())
    names = [p.name for s in samples for p in (s.center, s.left, s.right)]
    assert len(set(names)) == len(names)  # unique across worlds
    assert sorted(p.name for p in (out / "IMG").iterdir()) == sorted(names)  # and no frame without its row
    assert not (out / ".partial").exists()
    worlds = list(csv.DictReader((out / "worlds.csv").open()))
    assert [int(w["world_seed"]) for w in worlds] == [10, 11, 12] and {w["seed_range"] for w in worlds} == {"train"}
    covered = []
    for w in worlds:
        first, last = int(w["first_row"]), int(w["last_row"])
        covered += range(first, last + 1)
        assert samples[first - 1].center.name == w["first_image"] and samples[last - 1].center.name == w["last_image"]
        track = out / w["track_file"]
        assert file_sha256(track) == w["track_sha256"] and load_track(str(track)).length > 150
        assert int(w["interventions"]) == 0
    assert covered == list(range(1, len(samples) + 1))
    assert len({w["collect_seed"] for w in worlds}) == 3  # a distinct seed per world, derived from --seed
    assert int(worlds[1]["collect_seed"]) == world_collect_seed(3, 11)


def test_without_a_light_range_every_world_is_lit_by_the_collect_config(one_worker):
    assert {w["light_intensity"] for w in csv.DictReader((one_worker / "worlds.csv").open())} == {"1"}


def test_a_light_range_draws_each_worlds_sun_log_uniformly_and_deterministically():
    draws = [world_light_intensity(0, s, (0.4, 2.5)) for s in range(400)]
    assert min(draws) >= 0.4 and max(draws) <= 2.5
    assert draws == [world_light_intensity(0, s, (0.4, 2.5)) for s in range(400)]  # a function of the seeds only
    assert draws != [world_light_intensity(1, s, (0.4, 2.5)) for s in range(400)]
    below = sum(d < 1.0 for d in draws) / len(draws)  # 1.0 is the range's geometric centre
    assert 0.4 < below < 0.6
    assert world_light_intensity(5, 7, (1.3, 1.3)) == 1.3
    with pytest.raises(ValueError, match="light-range"):
        WorldsConfig(count=1, light_range=(2.0, 1.0))


def test_a_light_range_collects_each_world_under_its_own_sun_and_records_it(one_worker, tmp_path):
    out = tmp_path / "lit"
    collect_worlds(CONFIG, WorldsConfig(first_seed=10, count=3, generator=SHORT, light_range=(0.4, 2.5)), out)
    worlds = list(csv.DictReader((out / "worlds.csv").open()))
    lights = [float(w["light_intensity"]) for w in worlds]
    assert lights == [world_light_intensity(CONFIG.seed, s, (0.4, 2.5)) for s in (10, 11, 12)]
    assert min(lights) < 1.0 < max(lights)  # these seeds draw a darker and a brighter world
    plain = {w["world_seed"]: w for w in csv.DictReader((one_worker / "worlds.csv").open())}
    for w, light in zip(worlds, lights, strict=True):  # the same poses and frame names, only the light differs
        name = w["first_image"]
        assert name == plain[w["world_seed"]]["first_image"]
        lit = cv2.imread(str(out / "IMG" / name)).mean()
        base = cv2.imread(str(one_worker / "IMG" / name)).mean()
        assert (lit > base + 3) if light > 1.0 else (lit < base - 3)
    assert (out / "driving_log.csv").read_text().replace(str(out), "OUT") == _log(one_worker)


def test_two_workers_give_the_same_bytes_as_one(one_worker, tmp_path):
    out = tmp_path / "data"
    _collect(out, workers=2)
    assert _log(out) == _log(one_worker)
    assert (out / "worlds.csv").read_bytes() == (one_worker / "worlds.csv").read_bytes()
    for name in sorted(p.name for p in (one_worker / "IMG").iterdir())[::25]:
        assert (out / "IMG" / name).read_bytes() == (one_worker / "IMG" / name).read_bytes()
    for world in (one_worker / "worlds").iterdir():
        assert (out / "worlds" / world.name).read_bytes() == world.read_bytes()


def test_ctrl_c_leaves_no_log_and_resume_finishes_the_same_data_set(one_worker, tmp_path):
    out = tmp_path / "cut"

    def interrupt(outcome, done: int, total: int) -> None:
        if done == 1:
            raise KeyboardInterrupt

    cut = _collect(out, workers=1, on_world=interrupt)
    assert cut.interrupted and len(cut.outcomes) == 1
    assert not (out / "driving_log.csv").exists() and not (out / "worlds.csv").exists()
    with pytest.raises(ValueError, match="--resume"):
        _collect(out, workers=1)
    with pytest.raises(ValueError, match="other collect"):  # a resume with other arguments is refused
        collect_worlds(CollectConfig(cameras=1, rate_hz=1.0, seed=3), WorldsConfig(10, 3, generator=SHORT), out,
                       resume=True)
    resumed = _collect(out, workers=2, resume=True)
    assert resumed.resumed == 1 and not resumed.interrupted
    assert _log(out) == _log(one_worker)
    assert (out / "worlds.csv").read_bytes() == (one_worker / "worlds.csv").read_bytes()


def test_evaluation_worlds_are_refused_unless_explicitly_allowed(tmp_path, capsys):
    with pytest.raises(ValueError, match="held-out worlds must never be trained on"):
        WorldsConfig(first_seed=999_999, count=2)
    assert WorldsConfig(first_seed=1_000_000, count=2, allow_eval_worlds=True).seeds == [1_000_000, 1_000_001]
    out = tmp_path / "x"
    code = main(["collect", "--worlds", "2", "--world-seed", "1000000", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "eval range" in err and "--allow-eval-worlds" in err
    assert not out.exists()
    assert main(["collect", "--worlds", "1", "--track", "lake", "--out", str(out)]) == 2
    capsys.readouterr()
    assert main(["collect", "--track", "world:1000003", "--out", str(out)]) == 2  # the same world by name
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "eval range" in err and "--allow-eval-worlds" in err
    assert not out.exists()
    assert main(["collect", "--worlds", "1", "--world-config", '{"nope": 1}', "--out", str(out)]) == 2
    assert "unknown: nope" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["2:1", "0:1", "1:inf", "a:b", "1.5"])
def test_a_malformed_light_range_is_one_usage_line(bad, tmp_path, capsys):
    out = tmp_path / "x"
    with pytest.raises(SystemExit) as stop:
        main(["collect", "--worlds", "1", "--light-range", bad, "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and "--light-range: expected LO:HI" in err[-1] and not out.exists()


def test_a_light_range_needs_worlds(tmp_path, capsys):
    assert main(["collect", "--track", "lake", "--light-range", "0.5:2", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--light-range" in err and "--worlds" in err


def _cli(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tools.cli", "collect", "--worlds", "2", "--world-seed", "20",
                           "--cameras", "1", "--rate-hz", "1", "--world-config", SHORT_JSON, "--out", str(out),
                           *extra], cwd=ROOT, capture_output=True, text=True, timeout=240)


@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="Ray is not installed (pip extra: cluster)")
def test_the_ray_backend_gives_the_local_data_set(tmp_path):
    """In its own interpreter (the pytest process never imports Ray), as tests/test_evaluate_ray.py does."""
    local = _cli(tmp_path / "local", "--workers", "1")
    assert local.returncode == 0, local.stderr[-3000:]
    ray = _cli(tmp_path / "ray", "--workers", "2", "--backend", "ray")
    assert ray.returncode == 0, ray.stderr[-3000:]
    assert "world" in ray.stdout and "2 worlds" in ray.stdout
    assert _log(tmp_path / "ray") == _log(tmp_path / "local")
    assert (tmp_path / "ray" / "worlds.csv").read_bytes() == (tmp_path / "local" / "worlds.csv").read_bytes()
    assert len(list((tmp_path / "ray" / "IMG").iterdir())) == len(list((tmp_path / "local" / "IMG").iterdir()))


def test_a_real_ctrl_c_stops_every_worker_and_resume_completes(tmp_path):
    import os
    import signal
    import time

    out = tmp_path / "cut"
    args = [sys.executable, "-m", "tools.cli", "collect", "--worlds", "4", "--world-seed", "30", "--cameras", "1",
            "--rate-hz", "5", "--laps", "2", "--world-config", SHORT_JSON, "--workers", "2", "--out", str(out)]
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None and not list(out.glob(".partial/world-*/done.json")):
        time.sleep(0.02)
    if proc.poll() is not None:
        pytest.skip("the collection finished before it could be interrupted")
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the driver and its workers
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr[-3000:]
    assert "--resume" in stdout and not (out / "driving_log.csv").exists()
    resumed = subprocess.run([*args, "--resume"], cwd=ROOT, capture_output=True, text=True, timeout=240)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    samples, report = read_log(out)
    assert not report.skipped and len(list((out / "IMG").iterdir())) == len(samples)
    assert [int(w["world_seed"]) for w in csv.DictReader((out / "worlds.csv").open())] == [30, 31, 32, 33]
