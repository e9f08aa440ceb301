"""What the real lake frames showed ``rbc drive-log``'s road finder (issue 22): sunlit asphalt, stains, the
bridge's bricks and walls, and drivers who left the road, each on rendered frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_road_edges import _drive, _render

from tools.drivelog.loop import LoopRules, drive
from tools.drivelog.road import estimate_road


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
