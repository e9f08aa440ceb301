"""Track files: loading, validation errors, projection and cone placement."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tools.sim.track.cones import CONE_RADIUS, CONE_START_CLEARANCE, place_cones
from tools.sim.track.files import builtin_tracks, load_track, parse_track
from tools.sim.track.road import Track, TrackError


def oval(radius: float = 40.0, straight: float = 60.0, n: int = 24) -> list[list[float]]:
    """Control points of a stadium-shaped loop, counter-clockwise."""
    pts = []
    for k in range(n):
        a = -math.pi / 2 + 2 * math.pi * k / n
        cx = straight / 2 if math.cos(a) >= 0 else -straight / 2
        pts.append([cx + radius * math.cos(a), radius * math.sin(a)])
    return pts


def circle(radius: float, n: int = 16) -> list[list[float]]:
    return [[radius * math.cos(2 * math.pi * k / n), radius * math.sin(2 * math.pi * k / n)] for k in range(n)]


def minimal(**extra) -> dict:
    return {"name": "t", "version": 1, "centerline": circle(50.0), "road_width": 8.0, **extra}


@pytest.fixture(scope="module")
def ring() -> Track:
    return parse_track(minimal(), "ring")


# ---------------------------------------------------------------------------------------------- loading


def test_builtin_tracks_load_and_are_drivable():
    assert {"lake", "mountain"} <= set(builtin_tracks())
    lake, mountain = load_track("lake"), load_track("mountain")
    assert 850 < lake.length < 1300 and lake.lanes == 1
    assert mountain.lanes == 2 and mountain.camera_jitter.pitch_deg > 0
    for t in (lake, mountain):
        assert t.min_radius >= 15.0, f"{t.name} has a {t.min_radius:.1f} m curve"
        assert t.source == f"builtin:{t.name}"
    assert "bridge" in {lake.surface_at(s) for s in np.arange(0, lake.length, 5.0)}


def test_load_by_path_roundtrips(tmp_path: Path):
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(minimal(lanes=2)))
    t = load_track(path)
    assert t.source == str(path) and t.lanes == 2
    assert load_track(str(path)).digest == t.digest


def test_resampling_is_uniform_and_closed(ring: Track):
    assert ring.length == pytest.approx(2 * math.pi * 50.0, rel=1e-3)
    steps = np.linalg.norm(np.diff(np.r_[ring.centerline, ring.centerline[:1]], axis=0), axis=1)
    assert steps.max() - steps.min() < 0.02 and abs(steps.mean() - 0.5) < 0.01
    np.testing.assert_allclose(np.linalg.norm(ring.tangents, axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(1 / ring.curvature, 50.0, rtol=0.02)  # counter-clockwise: turning left
    np.testing.assert_allclose((ring.tangents * ring.normals).sum(1), 0.0, atol=1e-9)
    cross = ring.tangents[:, 0] * ring.normals[:, 1] - ring.tangents[:, 1] * ring.normals[:, 0]
    assert np.all(cross > 0)  # normals point left


@pytest.mark.parametrize(("data", "message"), [
    ({"version": 1, "centerline": circle(50), "road_width": 8}, "missing key 'name'"),
    ({"name": "t", "version": 1, "road_width": 8}, "missing key 'centerline'"),
    (minimal(road_widht=3), "unknown key(s) 'road_widht'"),
    (minimal(version=3), "unsupported version"),
    (minimal(version=True), "unsupported version"),
    (minimal(sky={"clouds": 0.5}), "need \"version\": 2"),
    (minimal(surfaces=[{"from_s": 1, "to_s": 20, "kind": "gravel"}]), "'gravel' (needs version 2)"),
    ({**minimal(), "centerline": [[0, 0], [10, 0], [10, 10]]}, "at least 4 points"),
    ({**minimal(), "centerline": [[0, 0], [10, 0], [10, "a"], [0, 10]]}, "centerline point 2"),
    ({**minimal(), "centerline": [[0, 0], [10, 0], [10, 0], [0, 10]]}, "coincide"),
    ({**minimal(), "road_width": -1}, "'road_width' = -1 is outside"),
    ({**minimal(), "road_width": "wide"}, "'road_width' must be a number"),
    (minimal(lanes=3), "'lanes' must be 1 or 2"),
    ({**minimal(), "centerline": circle(5.0)}, "curve radius 4.9 m"),
    ({**minimal(), "centerline": [[0, 0], [100, 100], [100, 0], [0, 100]]}, "crosses itself"),
    (minimal(surfaces=[{"from_s": 1, "to_s": 20, "kind": "ice"}]), "unknown surface kind 'ice'"),
    (minimal(surfaces=[{"from_s": 1, "to_s": 9999, "kind": "dirt"}]), "within the track length"),
    (minimal(scenery={"theme": "desert"}), "unknown theme 'desert'"),
    (minimal(scenery={"trees": {"cnt": 3}}), "unknown key(s) 'cnt' in 'scenery.trees'"),
    (minimal(sun={"elevation_deg": 0}), "'sun.elevation_deg' = 0 is outside"),
    ([1, 2], "top level must be a JSON object"),
])
def test_invalid_definitions_name_source_and_problem(data, message):
    with pytest.raises(TrackError) as err:
        parse_track(data, "bad.json")
    assert str(err.value).startswith("bad.json: ")
    assert message in str(err.value)


def test_overlapping_stretches_are_rejected():
    # a kidney-shaped loop whose indentation comes within 8 m of the far side; road plus shoulders need 10 m
    def kidney(depth: float) -> list[list[float]]:
        return [[-70, 0], [-50, -50], [0, -62], [50, -50], [70, 0], [50, 45], [22, 40], [18, 0], [12, -depth],
                [0, -depth - 4], [-12, -depth], [-18, 0], [-22, 40], [-50, 45]]

    assert parse_track({**minimal(), "centerline": kidney(46)}, "ok.json").min_radius > 15  # 12 m apart: fine
    with pytest.raises(TrackError, match=r"kidney\.json: road overlaps itself .* 8\.0 m apart"):
        parse_track({**minimal(), "centerline": kidney(50)}, "kidney.json")


def test_file_errors_name_the_file(tmp_path: Path):
    with pytest.raises(TrackError, match="no such track file"):
        load_track(tmp_path / "nope.json")
    bad = tmp_path / "broken.json"
    bad.write_text("{not json")
    with pytest.raises(TrackError, match=r"broken\.json: not valid JSON"):
        load_track(bad)


# ---------------------------------------------------------------------------------------------- queries


def test_project_sign_and_monotone_s(ring: Track):
    x, y, h = ring.point_at(10.0)
    left = (x - math.sin(h) * 1.5, y + math.cos(h) * 1.5)
    right = (x + math.sin(h) * 1.5, y - math.cos(h) * 1.5)
    assert ring.project(*left).cte == pytest.approx(1.5, abs=0.02)
    assert ring.project(*right).cte == pytest.approx(-1.5, abs=0.02)
    s_vals = [ring.project(*ring.point_at(s)[:2]).s for s in np.arange(0.3, ring.length - 1, 3.7)]
    assert np.all(np.diff(s_vals) > 0)


@pytest.mark.parametrize("name", ["lake", "mountain"])
def test_point_at_project_roundtrip(name: str):
    t = load_track(name)
    rng = np.random.default_rng(0)
    for s in rng.uniform(0, t.length, 40):
        x, y, h = t.point_at(s)
        for hint in (None, s + 3.0):
            p = t.project(x, y, hint)
            assert min(abs(p.s - s), t.length - abs(p.s - s)) < 0.02
            assert abs(p.cte) < 0.02
            assert math.cos(p.heading_rad - h) > 0.9999
    x, y, _ = t.point_at(t.length + 5.0)  # wraps
    assert t.project(x, y).s == pytest.approx(5.0, abs=0.02)


def test_hint_does_not_snap_to_far_stretch():
    t = load_track("mountain")
    x, y, _ = t.point_at(300.0)
    assert abs(t.project(x, y, hint_s=700.0).s - 300.0) < 0.05  # a stale hint falls back to a global search


def test_surface_at_wraps(ring: Track):
    t = parse_track(minimal(surfaces=[{"from_s": 300, "to_s": 10, "kind": "dirt"},
                                      {"from_s": 100, "to_s": 120, "kind": "bridge"}]), "s")
    assert t.surface_at(305) == "dirt" and t.surface_at(5) == "dirt" and t.surface_at(t.length + 5) == "dirt"
    assert t.surface_at(110) == "bridge" and t.surface_at(50) == "asphalt"
    kinds = t.surface_kinds()
    assert kinds[int(110 / t.spacing)] == 1 and kinds[int(50 / t.spacing)] == 0


# ---------------------------------------------------------------------------------------------- cones


def test_place_cones_is_deterministic_per_seed():
    t = load_track("lake")
    a, b, c = place_cones(t, 20, seed=1), place_cones(t, 20, seed=1), place_cones(t, 20, seed=2)
    assert a.shape == (20, 2)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    assert place_cones(t, 0, seed=1).shape == (0, 2)


@pytest.mark.parametrize("n", [10, 20])
def test_cones_block_half_the_road(n: int):
    t = load_track("lake")
    cones = place_cones(t, n, seed=3)
    proj = [t.project(x, y) for x, y in cones]
    sides = {math.copysign(1, p.cte) for p in proj}
    assert sides == {-1.0, 1.0}
    car_width = 1.9
    for p in proj:
        assert abs(p.cte) == pytest.approx(t.road_width / 4, abs=0.05)
        assert t.road_width / 2 - abs(p.cte) - CONE_RADIUS < car_width  # the blocked half is too narrow
        assert t.road_width / 2 + abs(p.cte) - CONE_RADIUS > car_width + 1.5  # the other half is free
        d = min(abs(p.s - t.start_s), t.length - abs(p.s - t.start_s))
        assert d >= CONE_START_CLEARANCE - 0.1
    s = np.sort([p.s for p in proj])
    assert np.diff(s).min() >= 24.9


def test_too_many_cones_is_an_error():
    with pytest.raises(ValueError, match="do not fit"):
        place_cones(load_track("lake"), 200, seed=0)
