"""What the real lake frames showed ``rbc drive-log``'s road finder (issue 22): sunlit asphalt, stains, the
bridge's bricks and walls, and drivers who left the road, each on rendered frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_road_edges import _drive, _render

from protocol.camera import pitch_matrix
from tools.drivelog.camera import DEFAULT_CAMERA
from tools.drivelog.loop import LoopRules, drive
from tools.drivelog.pitch import frame_pitch
from tools.drivelog.road import estimate_road
from tools.drivelog.road_view import Asphalt, _grid, frame_edges
from tools.drivelog.track import TRACK_PROFILES, detect_track


def test_sunlit_asphalt_is_still_road_and_only_the_edge_lines_end_it(tmp_path: Path) -> None:
    # issue 22: on the real lake the sun lightens strips of the asphalt across the road; the finder took them
    # for the road's end, found edges 5-6 m apart on a road 8-9 m wide, and took over from models that were
    # in the middle of the road (2002Esala: 9 of its 15 take-overs). Lightness alone no longer ends the road.
    sunlit = (-2.6, -1.0, (140, 140, 134))
    road = estimate_road(_drive(tmp_path, [_render(-3.5, 5.1, seed, sunlit) for seed in range(12)]), 2.6)
    assert np.all((road.left_m > -3.5) & (road.left_m < -3.15))
    assert np.all((road.right_m < 5.1) & (road.right_m > 4.75))


def test_a_false_edge_in_a_few_frames_is_outvoted_by_the_road_width_and_its_neighbours(tmp_path: Path) -> None:
    # a stain on the road (brown, as dirt) ends the road in 5 frames running: more than a running median
    # of 9 frames can outvote. Those frames' edges are 5 m apart on an 8 m road, so one of them is false;
    # the frames around agree where the road's middle is, so the right edge is believed and the left is
    # put a road width from it.
    stain = (-2.4, -1.6, (150, 120, 80))
    frames = [_render(-4.0, 4.0, s) for s in range(10)] + [_render(-4.0, 4.0, s, stain) for s in range(5)] \
        + [_render(-4.0, 4.0, s) for s in range(10, 20)]
    road = estimate_road(_drive(tmp_path, frames), 2.6)
    assert np.all((road.left_m > -4.0) & (road.left_m < -3.5))
    assert np.all((road.right_m < 4.0) & (road.right_m > 3.5))


def test_a_wider_stretch_is_kept_as_seen_and_a_lone_edge_the_neighbours_deny_is_not_believed(tmp_path: Path) -> None:
    # the lake's bridge is wider between its walls than the road between its lines: forcing the road's width
    # there put a false edge on the deck. And a side seen alone, 3 m from where the frames around put it,
    # is not believed: the frame takes the road from its neighbours.
    frames = [_render(-4.0, 4.0, s) for s in range(10)] + [_render(-6.0, 6.0, s) for s in range(5)] \
        + [_render(-4.0, 4.0, s) for s in range(10, 20)]
    lone = _render(-1.0, 30.0, 99)  # one edge 1 m left of the car, the right side beyond the view
    road = estimate_road(_drive(tmp_path, frames[:20] + [lone] + frames[20:]), 2.6)
    assert np.all(road.right_m[11:14] - road.left_m[11:14] > 11.0)
    assert road.left_m[20] == pytest.approx(-3.75, abs=0.25)


def test_a_bridge_of_bricks_shows_no_edge_and_takes_the_road_from_its_neighbours(tmp_path: Path) -> None:
    # on the lake's bridge the bricks ended the road in some rows at the car's side, scattered over metres in
    # others, and a wall seen alone was taken for the road's edge with the road's width put against it: edges
    # on the deck half a metre from the car. A row narrower than the car is not road, stops that scatter are
    # not an edge, and a lone edge that would put the recorded car over the other one is not believed.
    frames = [_render(-4.0, 4.0, s) for s in range(8)] + [_render(-6.0, 6.0, s, bricks=True) for s in range(6)] \
        + [_render(-4.0, 4.0, s) for s in range(8, 16)]
    road = estimate_road(_drive(tmp_path, frames), 2.6)
    assert not road.measured[8:14].any()
    assert np.all(road.left_m < -3.2) and np.all(road.right_m > 3.2)


def test_where_the_recorded_driver_left_the_road_the_person_drives_and_it_is_not_counted(tmp_path: Path) -> None:
    # AdiJoost drove onto the dirt twice: with no road in view the finder carried the road over from before,
    # and a model was taken over 10 times there for not following the driver across the dirt
    frames = [_render(-4.0, 4.0, s) for s in range(10)] + [_render(12.0, 20.0, s) for s in range(12)] \
        + [_render(-4.0, 4.0, s) for s in range(10, 15)] + [_render(12.0, 20.0, s) for s in range(12, 17)] \
        + [_render(-4.0, 4.0, s) for s in range(15, 25)]
    log = _drive(tmp_path, frames)
    road = estimate_road(log, 2.6)
    assert list(road.off_road) == [False] * 10 + [True] * 12 + [False] * 20  # 5 frames of dirt: not left
    asked: list[int] = []
    rules = LoopRules(handback_s=0.0, speed_limit_kmh=0.0)  # at the recorded speed: one step per frame
    result = drive(log, lambda view, i: asked.append(i) or 0.0, rules, snapshots=0, road=road)
    assert not set(asked) & set(range(10, 22)) and set(asked) >= set(range(22, 41))
    assert result.off_road_s == pytest.approx(1.2, abs=0.15)  # 12 frames of 0.1 s
    assert result.driving_time_s + result.off_road_s == pytest.approx(0.1 * (len(frames) - 1), abs=0.15)


# The jungle (issue 43): light grey asphalt, white edge lines, a white dashed centre line between two lanes,
# grass beyond, and rock walls that shade half the road.
_JUNGLE_ASPHALT = (160.0, 128.0, 130.0)  # OpenCV 8-bit Lab, as the public jungle recordings' median
_JUNGLE = Asphalt(np.array(_JUNGLE_ASPHALT, np.float32), np.array([20.0, 3.0, 3.0]))


def _top_down_jungle(left: float, centre: float, right: float, dash_rows: int, seed: int = 0) -> np.ndarray:
    """A top-down Lab view (rows 4-7 m ahead) of a jungle road: white edge lines at ``left`` and ``right``, grass
    beyond them, and a white dash at ``centre`` in its first ``dash_rows`` rows (a dash is 3 m long, the gap
    between dashes as long)."""
    xs, zs = _grid()
    rng = np.random.default_rng(seed)
    view = np.empty((len(zs), len(xs), 3), np.float64)
    view[:] = _JUNGLE_ASPHALT
    view[..., 0] += rng.normal(0, 8, view.shape[:2])
    view[:, (xs < left) | (xs > right)] = (120.0, 112.0, 150.0)  # grass
    for edge in (left, right):
        view[:, np.abs(xs - edge) < 0.1] = (235.0, 128.0, 130.0)
    view[:dash_rows, np.abs(xs - centre) < 0.1] = (250.0, 128.0, 130.0)
    return np.clip(view, 0, 255).astype(np.uint8)


def test_the_jungles_dashed_centre_line_lies_inside_the_road() -> None:
    # issue 43: on the jungle the dash 1.5 m right of a car in the left lane ended the road in the rows that saw
    # it ("road edges -1.0 / +5.6 m" beside a car in the middle of its lane); the jungle's profile closes gaps of
    # the asphalt's chroma up to 0.6 m wide, whatever their lightness, so both lanes are the road
    view = _top_down_jungle(-3.8, 1.5, 5.5, dash_rows=4)
    assert frame_edges(view, _JUNGLE)[1] == pytest.approx(1.4, abs=0.15)  # the lake's rule: the dash is an edge
    left, right = frame_edges(view, _JUNGLE, TRACK_PROFILES["jungle"].line_gap_m)
    assert -3.95 < left < -3.6 and 5.35 < right < 5.65  # within the edge lines (0.2 m wide)


def test_a_jungle_edge_line_still_ends_the_road() -> None:
    # the edge line has asphalt on one side only: nothing to close, and the grass beyond has another chroma
    for seed in range(5):
        left, right = frame_edges(_top_down_jungle(-4.0, 0.5, 3.0, dash_rows=7, seed=seed), _JUNGLE, 0.6)
        assert -4.15 < left < -3.75 and 2.75 < right < 3.15


def _render_jungle(left: float, right: float, seed: int, shade_from: float | None = None,
                   dash_phase: float = 0.0, camera_x: float = 0.0, pitch_deg: float | None = None) -> np.ndarray:
    """A centre frame of a straight jungle road: white edge lines at ``left`` and ``right`` (m, + right), a dashed
    white centre line between them (3 m dashes, 3 m gaps), grass beyond; ``shade_from``: the road shaded (dark,
    a little blue) from there to its right edge, as a rock wall's shadow. ``camera_x``: the camera that far to
    the right (a side camera); ``pitch_deg``: the ground seen at this pitch (a hill; None: the camera's)."""
    cam = DEFAULT_CAMERA
    v, u = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    rays = np.linalg.inv(cam.intrinsics()) @ np.stack([u.ravel(), v.ravel(), np.ones(u.size)])
    level = pitch_matrix(cam.pitch_deg if pitch_deg is None else pitch_deg).T @ rays
    down = level[1] > 1e-6
    t = np.where(down, cam.height_m / np.where(down, level[1], 1.0), 0.0)
    x, z = (t * level[0]).reshape(u.shape) + camera_x, (t * level[2]).reshape(u.shape)
    ground = down.reshape(u.shape)
    img = np.empty((cam.height, cam.width, 3), np.float64)
    img[:] = (120, 160, 220)
    img[ground] = (70, 105, 40)  # grass
    road = ground & (x > left - 0.12) & (x < right + 0.12)
    img[road] = (165, 165, 163)
    middle = (left + right) / 2
    lines = (np.abs(x - left) < 0.12) | (np.abs(x - right) < 0.12) \
        | ((np.abs(x - middle) < 0.1) & (((z + dash_phase) // 3.0) % 2 == 0))
    img[road & lines] = 240
    if shade_from is not None:
        img[road & (x > shade_from)] *= (0.28, 0.30, 0.36)
    img += np.random.default_rng(seed).normal(0, 5, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def test_a_jungle_road_is_found_whole_in_sun_and_shade(tmp_path: Path) -> None:
    # the car 2 m right of the road's middle (in the right lane), the dashes passing by; in some frames a wall's
    # shadow covers the road from 1 m left of the car to the right edge
    frames = [_render_jungle(-6.0, 2.0, s, shade_from=-1.0 if s % 3 == 0 else None, dash_phase=0.8 * s)
              for s in range(15)]
    road = estimate_road(_drive(tmp_path, frames), 2.6, track="jungle")
    assert road.track == "jungle"
    assert np.all(np.abs(road.right_m - 2.0) < 0.35)
    assert np.all(road.left_m < -5.0)  # the far edge line, often beyond the view: never the dashes at -2 m
    assert road.measured.all()
    lake = estimate_road(_drive(tmp_path, frames), 2.6, track="lake")
    assert not lake.measured[::3].any()  # the lake's rule: shaded asphalt is not road


def test_the_track_is_told_from_the_asphalts_colour() -> None:
    # the public recordings' medians at the edges of each track's range (scripts of issue 43)
    assert detect_track(np.array([147.0, 124.0, 135.0])) == "lake"  # necyk-lake, the lightest lake asphalt
    assert detect_track(np.array([121.0, 125.0, 136.0])) == "lake"
    assert detect_track(np.array([147.0, 128.0, 131.0])) == "jungle"  # atul799, the darkest jungle asphalt
    assert detect_track(np.array([148.0, 128.0, 132.0])) == "jungle"
    assert detect_track(np.array([76.0, 129.0, 125.0])) == "mountain"  # AVMktl-2, the lightest mountain


def test_the_grounds_pitch_is_read_off_the_side_cameras() -> None:
    # issue 43: on the jungle's hills the road ahead is not the plane the car stands on; the centre frame
    # re-projected to each side camera's place matches the real side frames best at the ground's own pitch
    side = DEFAULT_CAMERA.side_offset_m
    for pitch in (2.0, 6.2, 12.0):
        frames = [_render_jungle(-3.0, 5.0, seed, dash_phase=0.7 * seed, camera_x=x, pitch_deg=pitch)
                  for seed, x in ((1, 0.0), (2, -side), (3, side))]
        found, correlation = frame_pitch(*frames)
        assert found == pytest.approx(pitch, abs=1.0) and correlation > 0.6
    assert np.isnan(frame_pitch(frames[0], None, None)[0])
