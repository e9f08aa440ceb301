"""``rbc drive-log``'s road rule (issue 22): the road's edge lines are found in the recorded frames, and a
take-over means the car's side passed one, not 1 m from one driver's line on a road 9 m wide."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from protocol.camera import pitch_matrix
from protocol.datalog import DataLogError, read_log
from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, ViewSynthesizer, ground_to_pixels
from tools.drivelog.loop import LoopRules, _view, lane_limits
from tools.drivelog.path import RecordedDrive, recorded_drive
from tools.drivelog.road import RoadEdges, estimate_road

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
ASPHALT, LINE, VERGE, SKY = (118, 118, 114), (190, 170, 60), (150, 120, 80), (120, 160, 220)


def _render(road_left: float, road_right: float, seed: int = 0,
            patch: tuple[float, float, tuple[int, int, int]] | None = None, bricks: bool = False) -> np.ndarray:
    """A centre frame of a straight road between ``road_left`` and ``road_right`` (m, + right), yellow
    edge lines inside, dirt outside; grainy asphalt as the lake's. ``patch``: (from, to, colour), a strip
    of the road along it painted that colour (sunlit asphalt, a stain). ``bricks``: a deck of bricks
    (0.4 m, pale, between dark mortar lines) between dark walls, as the lake's bridge, without edge lines."""
    cam = DEFAULT_CAMERA
    v, u = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    rays = np.linalg.inv(cam.intrinsics()) @ np.stack([u.ravel(), v.ravel(), np.ones(u.size)])
    level = pitch_matrix(cam.pitch_deg).T @ rays
    down = level[1] > 1e-6
    t = np.where(down, cam.height_m / np.where(down, level[1], 1.0), 0.0)
    x = (t * level[0]).reshape(u.shape)
    z = (t * level[2]).reshape(u.shape)
    img = np.empty((cam.height, cam.width, 3), np.float64)
    img[:] = SKY
    ground = down.reshape(u.shape)
    on_road = ground & (x > road_left) & (x < road_right)
    img[ground] = VERGE
    img[on_road] = ASPHALT
    if patch is not None:
        img[on_road & (x > patch[0]) & (x < patch[1])] = patch[2]
    if bricks:
        img[ground] = (20, 20, 20)  # the walls
        img[on_road] = (150, 140, 130)  # pale bricks, near the asphalt's colour, between dark mortar lines
        mortar = (np.abs(x / 0.4 - np.round(x / 0.4)) < 0.12) | (np.abs(z / 0.4 - np.round(z / 0.4)) < 0.12)
        img[on_road & mortar] = 40
    else:
        for edge in (road_left, road_right):
            img[ground & (np.abs(x - edge) < 0.12)] = LINE
    rng = np.random.default_rng(seed)
    img += rng.normal(0, 6, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def _drive(tmp_path: Path, frames: list[np.ndarray]) -> RecordedDrive:
    paths = []
    for i, frame in enumerate(frames):
        p = tmp_path / f"center_{i:03d}.jpg"
        cv2.imwrite(str(p), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90])
        paths.append(p)
    n = len(paths)
    return RecordedDrive(paths, np.zeros(n), np.full(n, 8.0), np.r_[np.full(n - 1, 0.1), 0.0], np.zeros(n, np.int64),
                         np.arange(n) * 0.8)


def test_the_edge_lines_of_a_rendered_road_are_found_where_they_are(tmp_path: Path) -> None:
    # the driver 0.8 m left of the middle of an 8.6 m road: its lines at -3.5 m and +5.1 m. What is found is
    # where the asphalt ends, the inner side of the 0.24 m line (JPEG's chroma blurs it a little further in)
    road = estimate_road(_drive(tmp_path, [_render(-3.5, 5.1, seed) for seed in range(12)]), 2.6)
    assert road.measured_share == 1.0
    assert np.all((road.left_m > -3.5) & (road.left_m < -3.15))
    assert np.all((road.right_m < 5.1) & (road.right_m > 4.75))
    assert road.width_m == pytest.approx(8.6 - 0.45, abs=0.2)


def test_frames_that_show_no_road_take_it_from_their_neighbours(tmp_path: Path) -> None:
    frames = [_render(-4.0, 4.0, s) for s in range(6)] + [_render(-4.0, 4.0, 9)[:, ::-1] * 0 + 200] * 3 \
        + [_render(-3.0, 5.0, s) for s in range(6)]
    road = estimate_road(_drive(tmp_path, frames), 2.6)
    assert list(road.measured) == [True] * 6 + [False] * 3 + [True] * 6
    before, after = road.left_m[0], road.left_m[-1]
    assert before == pytest.approx(-4.0, abs=0.35) and after == pytest.approx(-3.0, abs=0.35)
    assert np.all(np.diff(road.left_m) >= 0) and before < road.left_m[7] < after  # between its neighbours


def test_the_car_leaves_the_lane_when_its_side_passes_an_edge_line() -> None:
    road = RoadEdges(np.array([-4.0, -1.2]), np.array([4.5, 0.9]), np.array([True, True]), 8.5)
    limits = lane_limits(LoopRules(), road, 2)
    assert limits[0] == pytest.approx([-3.05, 3.55])  # the car is 1.9 m wide
    # a driver who was already at the lines: the car may still move 0.5 m towards them
    assert limits[1] == pytest.approx([-0.5, 0.5])
    assert lane_limits(LoopRules(lane="path", max_offset_m=1.0), None, 2).tolist() == [[-1.0, 1.0]] * 2
    with pytest.raises(ValueError, match="road"):
        lane_limits(LoopRules(), None, 2)


def test_a_car_near_a_side_camera_is_shown_that_camera_with_its_own_bonnet() -> None:
    log = recorded_drive(read_log(SAMPLE)[0])
    synth, cam = ViewSynthesizer(), DEFAULT_CAMERA
    left, centre = read_jpeg_file(log.side_frame(3, "left")), read_jpeg_file(log.frames[3])
    view = _view(synth, log, 3, -cam.side_offset_m, 0.0, 0.0, LoopRules(), cam)
    assert np.array_equal(view[:cam.bonnet_row], left[:cam.bonnet_row])
    assert np.array_equal(view[cam.bonnet_row:], centre[cam.bonnet_row:])
    near = _view(synth, log, 3, -0.3, 0.0, 0.0, LoopRules(), cam)  # closer to the centre camera
    assert np.array_equal(near, synth.view(centre, -0.3, 0.0))
    only_centre = _view(synth, log, 3, -cam.side_offset_m, 0.0, 0.0, LoopRules(views="centre"), cam)
    assert np.array_equal(only_centre, synth.view(centre, -cam.side_offset_m, 0.0))


def test_ground_points_land_where_the_view_synthesis_puts_them() -> None:
    u, v = ground_to_pixels(DEFAULT_CAMERA, np.array([0.0, 2.0]), np.array([1e6, 10.0]))
    assert v[0] == pytest.approx(DEFAULT_CAMERA.horizon_row, abs=1e-3) and u[0] == pytest.approx(160.0)
    assert u[1] > 160.0 and v[1] > DEFAULT_CAMERA.horizon_row
    assert math.isfinite(u[1])


def test_rbc_data_road_writes_one_row_per_centre_frame(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from models.data.roadfile import ROAD_FILE, read_road_middles
    from tools.cli import main

    data = tmp_path / "rec"
    shutil.copytree(SAMPLE, data)
    assert main(["data", "road", str(data)]) == 0
    assert "m wide" in capsys.readouterr().out
    middles = read_road_middles(data / ROAD_FILE)
    samples, _ = read_log(data)
    assert sorted(middles) == sorted(Path(s.center).name for s in samples)
    assert all(abs(m) < 4.0 for m in middles.values())  # the driver is on the road


def _sample_with_road(tmp_path: Path, middle_of: dict[str, float] | None = None) -> Path:
    from models.data.roadfile import ROAD_FILE, write_road_file

    data = tmp_path / "rec"
    shutil.copytree(SAMPLE, data)
    frames = [Path(s.center) for s in read_log(data)[0]]
    middle = np.array([(middle_of or {}).get(f.name, 0.5 * (k % 5 - 2)) for k, f in enumerate(frames)])
    write_road_file(data / ROAD_FILE, frames, middle - 4.2, middle + 4.2, np.ones(len(frames), bool))
    return data


def test_the_centre_gain_adds_steering_towards_the_roads_middle_and_never_scores_it(tmp_path: Path) -> None:
    from models.data.behavior import pipeline_for
    from models.data.roadfile import ROAD_FILE, read_road_middles
    from models.data.trainingdata import DataOptions, prepare_data

    data = _sample_with_road(tmp_path)
    pipeline = pipeline_for("simplistic", "shallow", "ours")
    plain = prepare_data([data], pipeline, 2, DataOptions(), workers=1)
    centred = prepare_data([data], pipeline, 2, DataOptions(centre_gain=0.1), workers=1)
    middles = read_road_middles(data / ROAD_FILE)
    expected = np.clip(plain.targets + 0.1 * np.array([middles[Path(s.center).name]
                                                       for s in centred.dataset.samples]), -1, 1)
    assert np.allclose(centred.targets, expected, atol=1e-6) and not np.allclose(centred.targets, plain.targets)
    assert np.array_equal(centred.steering, plain.steering)  # validation still scores the recorded steering


def test_the_centre_gain_without_a_road_file_is_one_clear_error(tmp_path: Path) -> None:
    from models.data.behavior import pipeline_for
    from models.data.trainingdata import DataOptions, prepare_data
    from protocol.datalog import DataLogError

    data = tmp_path / "rec"
    shutil.copytree(SAMPLE, data)
    with pytest.raises(DataLogError, match="rbc data road"):
        prepare_data([data], pipeline_for("simplistic", "shallow", "ours"), 2, DataOptions(centre_gain=0.1), workers=1)
    (data / "road_edges.csv").write_text("frame,left,right\n")
    with pytest.raises(DataLogError, match="not a road file"):
        prepare_data([data], pipeline_for("simplistic", "shallow", "ours"), 2, DataOptions(centre_gain=0.1), workers=1)


def test_an_unknown_lane_rule_or_view_source_is_refused() -> None:
    with pytest.raises(ValueError, match="lane"):
        LoopRules(lane="lanes")
    with pytest.raises(ValueError, match="views"):
        LoopRules(views="left")


def test_the_edge_pull_acts_beyond_the_margin_each_camera_at_its_own_offset() -> None:
    from models.augmentation.augment import CENTER, LEFT, RIGHT, AugmentSpec, edge_pull

    spec = AugmentSpec(edge_gain=0.2, edge_margin=1.5, side_camera_m=1.0)
    middles = np.array([0.5, 0.5, 0.5, -2.0, 2.0])  # the road's middle from the centre camera, + right
    camera = np.array([CENTER, LEFT, RIGHT, CENTER, CENTER])
    pull = edge_pull(middles, camera, spec)
    # within the margin nothing; the left camera stands 1.5 m left of the middle: still nothing; 2 m: 0.5 m over
    assert np.allclose(pull, [0.0, 0.0, 0.0, -0.1, 0.1])
    assert np.allclose(edge_pull(np.array([1.0]), np.array([LEFT]), spec), [0.1])  # 2.5 m left of it: steer right
    assert np.allclose(edge_pull(np.array([-1.0]), np.array([RIGHT]), spec), [-0.1])
    assert np.array_equal(edge_pull(np.array([np.nan]), np.array([CENTER]), spec), [0.0])


def test_the_edge_pull_moves_labels_only_where_asked_and_draws_nothing(tmp_path: Path) -> None:
    from models.augmentation.augment import AugmentSpec, draw_params

    steering, sides = np.zeros(64), np.ones(64, bool)
    middles = np.linspace(-3, 3, 64)
    plain = draw_params(steering, sides, AugmentSpec(), np.random.default_rng(0), middles)
    pulled = draw_params(steering, sides, AugmentSpec(edge_gain=0.3), np.random.default_rng(0), middles)
    assert np.array_equal(plain.camera, pulled.camera) and np.array_equal(plain.flip, pulled.flip)
    moved = plain.steering != pulled.steering
    assert moved.any() and not moved.all()
    # a flipped centre frame sees the mirrored road: its pull is mirrored with it
    diff = (pulled.steering - plain.steering)[moved]
    want = np.sign(middles[moved]) * np.where(pulled.flip[moved], -1, 1)
    assert np.all(np.sign(diff) == want)


def test_rbc_train_keeps_the_road_middles_for_the_edge_pull(tmp_path: Path) -> None:
    from models.data.behavior import pipeline_for
    from models.data.trainingdata import DataOptions, prepare_data

    data = _sample_with_road(tmp_path)
    pipeline = pipeline_for("simplistic", "shallow", "ours")
    plain = prepare_data([data], pipeline, 2, DataOptions(), workers=1)
    kept = prepare_data([data], pipeline, 2, DataOptions(road_middles=True), workers=1)
    assert plain.middles is None and kept.middles is not None and np.any(kept.middles != 0)
    assert np.array_equal(kept.targets, plain.targets)  # the pull is drawn per batch, with the camera
    bare = tmp_path / "bare"  # a recording without a road file (a two-lane road: keep its lane) is not pulled
    shutil.copytree(SAMPLE, bare)
    both = prepare_data([data, bare], pipeline, 2, DataOptions(road_middles=True), workers=1)
    unknown = np.isnan(both.middles)
    assert unknown.sum() == len(both.middles) // 2 and not np.isnan(both.middles[~unknown]).any()
    with pytest.raises(DataLogError, match="no recording has a road_edges.csv"):
        prepare_data([bare], pipeline, 2, DataOptions(road_middles=True), workers=1)


def test_the_edge_gain_reaches_the_augmentation_and_a_bad_one_is_refused(tmp_path: Path) -> None:
    from models.training.train_config import TrainConfig
    from protocol.camera import SIDE_OFFSET_M as SIDE_CAMERA_OFFSET_M

    config = TrainConfig(data=["d"], out=str(tmp_path), edge_gain=0.2, edge_margin=2.0)
    spec = config.pipeline().augment
    assert (spec.edge_gain, spec.edge_margin, spec.side_camera_m) == (0.2, 2.0, SIDE_CAMERA_OFFSET_M)
    assert config.data_options().road_middles and not TrainConfig(data=["d"], out="o").data_options().road_middles
    for bad in ({"edge_gain": -0.1}, {"edge_gain": 2.0}, {"edge_margin": -1.0}):
        with pytest.raises(ValueError, match="edge"):
            TrainConfig(data=["d"], out=str(tmp_path), **bad)


def test_rbc_data_road_public_measures_every_track_and_says_what_is_missing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The jungle and mountain roads are found too, so --public measures the whole list, not only the lake."""
    from tools.cli import main
    from tools.realdata.recordings import public_recordings

    every = public_recordings()
    assert {r.track for r in every} == {"lake", "jungle", "mountain"}
    shutil.copytree(SAMPLE, tmp_path / every[0].name)
    assert main(["data", "road", "--public", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"{len(every) - 1} public recordings not under {tmp_path}" in err and "rbc data fetch" in err
    assert not (tmp_path / every[0].name / "road_edges.csv").exists()  # nothing measured before the check
    assert main(["data", "road"]) == 2
    assert "--public ROOT" in capsys.readouterr().err
