"""Procedural worlds: deterministic per seed, valid over many seeds, drivable, reserved seed ranges, rbc world."""

from __future__ import annotations

import json
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest

from tools.cli import main
from tools.sim.track.files import load_track, parse_track
from tools.sim.track.geometry import closest_overlap
from tools.sim.track.road import TrackError
from tools.sim.worldgen import (
    SEED_RANGES,
    WorldGenConfig,
    check_world,
    generate_world,
    seed_range_of,
    world_seed_range,
    write_world,
)
from tools.sim.worldgen.drive_check import drive_check
from tools.sim.worldgen.generate import resolve_track_name

FAST = WorldGenConfig(drive_check=False)


def test_same_seed_same_document_other_seed_other_world():
    a, b = generate_world(1_000_123, FAST), generate_world(1_000_123, FAST)
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)
    assert generate_world(1_000_124, FAST)["centerline"] != a["centerline"]
    assert generate_world(7) == generate_world(7)  # with the drive check as well


@pytest.mark.parametrize("start", [0, 1_000_000])
def test_worlds_are_valid_over_many_seeds(start):
    cfg = FAST
    themes = set()
    for seed in range(start, start + 25):
        doc = generate_world(seed, cfg)
        assert check_world(doc, cfg) == [], seed
        track = parse_track(json.loads(json.dumps(doc)), f"world {seed}")
        assert track.version == 2 and track.name == f"world-{seed}"
        assert cfg.min_length_m <= track.length <= cfg.max_length_m
        assert track.min_radius >= cfg.min_radius_m
        assert cfg.min_road_width_m <= track.road_width <= cfg.max_road_width_m
        # independent of the generator's own check: the road keeps clear of itself by the margin
        step = 2
        p = track.centerline[::step]
        clearance = track.road_width + 2 * track.shoulder_width + cfg.clearance_margin_m
        assert closest_overlap(p, track.s[::step], track.length, clearance) is None, seed
        themes.add(track.scenery.theme)
    assert len(themes) >= 4


def test_the_distribution_covers_what_was_asked_for():
    docs = [generate_world(s, FAST) for s in range(2_000_000, 2_000_040)]
    tracks = [parse_track(d, d["name"]) for d in docs]
    assert min(t.min_radius for t in tracks) < 12.0  # hairpins near the limit
    assert max(t.min_radius for t in tracks) > 18.0  # and worlds of sweepers
    assert {t.lanes for t in tracks} == {1, 2}
    kinds = {s.kind for t in tracks for s in t.surfaces}
    assert {"bridge", "concrete", "gravel", "dirt", "worn_asphalt"} <= kinds
    assert {t.edges.line_style for t in tracks} == {"solid", "dashed", "none"}
    assert min(t.scenery.trees.count for t in tracks) == 0 and max(t.scenery.trees.count for t in tracks) > 300
    assert min(t.sun_elevation_deg for t in tracks) < 20 and max(t.sun_elevation_deg for t in tracks) > 55


def test_default_worlds_never_draw_udacity_themes_and_asked_for_ones_look_like_the_real_tracks():
    from tools.sim.track.themes import GENERIC_THEMES, UDACITY_THEMES

    assert FAST.themes == GENERIC_THEMES and not set(UDACITY_THEMES) & set(GENERIC_THEMES)
    assert not {generate_world(s, FAST)["scenery"]["theme"] for s in range(2_000_000, 2_000_030)} & set(UDACITY_THEMES)
    cfg = WorldGenConfig(drive_check=False, themes=UDACITY_THEMES)
    seen = set()
    for seed in range(2_000_000, 2_000_012):
        doc = generate_world(seed, cfg)
        track = parse_track(json.loads(json.dumps(doc)), doc["name"])
        theme = track.scenery.theme
        seen.add(theme)
        assert theme in UDACITY_THEMES
        assert {s.kind for s in track.surfaces} <= {"asphalt", "bridge"}  # the real tracks are paved
        if theme == "udacity_lake":  # yellow edge lines, the light concrete kerb strip, coarse asphalt
            edges = track.edges
            assert (edges.line_color, edges.line_style, edges.verge) == ("yellow", "solid", "concrete")
            assert track.appearance.grain >= 2.0
        if theme == "udacity_jungle":
            assert (track.edges.line_color, track.edges.center_color, track.edges.center_style) == (
                "white", "white", "dashed")
    assert len(seen) >= 2
    # the same seed keeps its road whatever it is dressed as
    assert generate_world(2_000_003, cfg)["centerline"] == generate_world(2_000_003, FAST)["centerline"]


def test_seed_ranges_are_disjoint_and_named():
    for (_, a), (_, b) in combinations(SEED_RANGES.items(), 2):
        assert set(range(a.start, a.stop, 9973)).isdisjoint(b) and (a.stop <= b.start or b.stop <= a.start)
    assert world_seed_range("train") == range(0, 1_000_000)
    assert world_seed_range("eval") == range(1_000_000, 2_000_000)
    assert seed_range_of(0) == "train" and seed_range_of(999_999) == "train"
    assert seed_range_of(1_000_000) == "eval" and seed_range_of(10**9) is None
    with pytest.raises(ValueError, match="unknown seed range"):
        world_seed_range("test")
    with pytest.raises(ValueError, match="integer >= 0"):
        generate_world(-1)


@pytest.mark.parametrize("seed", [3, 1_000_004, 1_000_011])
def test_autopilot_laps_generated_worlds_at_eta_100_with_both_cars(seed, tmp_path):
    path = write_world(seed, tmp_path / "w.json")
    for vehicle in ("kinematic", "dynamic"):
        check = drive_check(path, vehicle)
        assert check.ok and check.eta == 100.0 and check.lane_departures == 0, (seed, vehicle, check)
        assert check.mean_speed_kmh > 20.0


def test_rbc_world_writes_a_loadable_track_file_and_says_its_range(tmp_path, capsys):
    out = tmp_path / "world.json"
    assert main(["world", "--seed", "1000002", "--out", str(out), "--no-drive-check"]) == 0
    assert "eval range 1,000,000-1,999,999" in capsys.readouterr().out
    track = load_track(str(out))
    assert track.name == "world-1000002" and track.version == 2
    assert main(["world", "--range", "train", "--seed", "5", "--count", "2", "--out", str(tmp_path / "many"),
                 "--no-drive-check"]) == 0
    assert sorted(p.name for p in (tmp_path / "many").iterdir()) == ["world-5.json", "world-6.json"]


@pytest.mark.parametrize(("argv", "message"), [
    (["--seed", "-3", "--out", "x.json"], "--seed must be >= 0"),
    (["--seed", "3"], "nothing to write"),
    (["--out", "x.json"], "give --seed S or --range NAME"),
    (["--seed", "1", "--count", "0", "--out", "x"], "--count must be 1..100000"),
    (["--range", "eval", "--seed", "999999", "--count", "5", "--out", "x"], "runs past the eval range"),
])
def test_rbc_world_bad_arguments_give_one_line(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["world", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("rbc world: error: ") and message in err and "\n" not in err and "Traceback" not in err


def test_world_seed_names_the_generated_world_wherever_a_track_is_asked_for(tmp_path, capsys):
    out = tmp_path / "world.json"
    assert main(["world", "--seed", "2000001", "--out", str(out)]) == 0
    resolved = resolve_track_name("world:2000001")
    assert Path(resolved).read_bytes() == out.read_bytes()  # the world rbc world writes, byte for byte
    assert resolve_track_name("world:2000001") == resolved and resolve_track_name("lake") == "lake"
    for bad in ("world:", "world:-1", "world:1e6", "world: 5"):
        with pytest.raises(TrackError, match="world:SEED"):
            resolve_track_name(bad)
    with pytest.raises(TrackError, match="loaded from its file"):
        load_track("world:2000001")
    assert main(["sim", "--track", "world:x7", "--autopilot"]) == 2
    err = capsys.readouterr().err.strip()
    assert "world:SEED" in err and "\n" not in err and "Traceback" not in err


def test_generated_frames_are_plausible():
    """Road in view: the bottom centre of the frame on the start straight differs from the sky."""
    from tools.sim.render.renderer import Renderer
    from tools.sim.render.world import Pose, World

    track = parse_track(generate_world(1_000_001, FAST), "w")
    x, y, h = track.point_at(track.start_s + 10)
    img = Renderer(World(track), seed=1).render(Pose(x, y, h))
    assert img.shape == (160, 320, 3)
    road, sky = img[140:, 150:170].astype(float), img[:20].astype(float)
    assert np.abs(road.mean((0, 1)) - sky.mean((0, 1))).sum() > 30


def test_rbc_world_contact_sheet(tmp_path):
    import cv2

    out = tmp_path / "sheet.png"
    assert main(["world", "--seed", "11", "--sheet", str(out), "--no-drive-check"]) == 0
    img = cv2.imread(str(out))
    assert img is not None and img.shape[0] > 160 and img.std() > 20
