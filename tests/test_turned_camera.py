"""The turned-camera augmentation (not in the paper): its label, its geometry, and the edge it must not leave."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from drive_server.serving.preprocess import to_input_tensor
from models.augmentation import augment, geometry, reference
from models.augmentation.augment import AugmentSpec, draw_params
from models.augmentation.fastaug import FastAugmenter
from models.data.framecache import FrameCache
from protocol.facts import CAMERAS

NONE = dict(perspective=0.0, shadow=0.0, brightness=0.0, flip=0.0, pan=0.0, tilt=0.0)


def test_turned_camera_label_steers_back_and_flip_mirrors_it() -> None:
    spec = AugmentSpec(**{**NONE, "yaw_aug": 1.0, "yaw_range": 6.0, "yaw_gain": 0.5})
    steering = np.full(400, 0.2)
    p = draw_params(steering, np.zeros(400, bool), replace(spec, flip=0.5), np.random.default_rng(1))
    assert p.turned.all() and np.abs(p.yaw_deg).max() <= 6.0 and np.ptp(p.yaw_deg) > 10
    unflipped = 0.2 - 0.5 * p.yaw_deg / 25  # turned right (+): steer left, half the turn at once
    expect = np.where(p.flip, -unflipped, unflipped)
    assert np.allclose(p.steering, expect, atol=1e-6)
    # without it the generator is consumed exactly as before the augmentation existed
    a = draw_params(steering, np.ones(400, bool), AugmentSpec(), np.random.default_rng(2))
    b = draw_params(steering, np.ones(400, bool), replace(AugmentSpec(), yaw_range=3.0), np.random.default_rng(2))
    assert a.yaw is None and np.array_equal(a.steering, b.steering) and np.array_equal(a.pan_xy, b.pan_xy)


def test_turned_camera_is_the_closed_loops_rotation() -> None:
    from tools.drivelog.camera import DEFAULT_CAMERA, view_homographies

    for rad in (-0.1, 0.03):
        _, far = view_homographies(DEFAULT_CAMERA, 0.0, rad)
        pull = geometry.yaw_pullbacks(320, 160, np.array([rad]), DEFAULT_CAMERA.vfov_deg, DEFAULT_CAMERA.pitch_deg)[0]
        index = geometry.translate(-0.5, -0.5) @ pull @ geometry.translate(0.5, 0.5)
        assert np.allclose(index / index[2, 2], far / far[2, 2], atol=1e-9)
    spec = AugmentSpec()
    assert (spec.camera_vfov_deg, spec.camera_pitch_deg) == (DEFAULT_CAMERA.vfov_deg, DEFAULT_CAMERA.pitch_deg)
    # turning right moves the road to the left of the picture
    img = np.zeros((160, 320, 3), np.uint8)
    img[:, 150:170] = 255
    right = reference.turn(img, 4.0, spec)
    cols = np.flatnonzero(right[120, :, 0] > 128)
    assert abs(cols.mean() - (160 - 138.56 * math.tan(math.radians(4.0)))) < 1.5  # f tan(psi) to the left


@pytest.mark.parametrize("range_deg", [3.0, 6.0, 10.0])
def test_a_turned_view_has_no_edge_that_tells_its_turn(range_deg: float) -> None:
    """The repeated edge a turn leaves is blanked on both sides of every input (the closed loop's views have
    that edge too: a network that read the turn from it would score there what it cannot do in Unity)."""
    from models.training.train_config import TrainConfig

    pipeline = TrainConfig(data=["x"], out="y", yaw_aug=1.0, yaw_range=range_deg, crop_top=64,
                           crop_bottom=136).pipeline()
    contract, spec = pipeline.contract, replace(pipeline.augment, **NONE)
    b = contract.blank_columns
    ramp = np.tile(np.linspace(20, 235, contract.width).astype(np.uint8)[None, :, None], (contract.height, 1, 3))
    cache = FrameCache(np.broadcast_to(ramp, (3, 2, *ramp.shape)).copy(), CAMERAS, contract, np.ones(2, bool), [])
    p = draw_params(np.zeros(2), np.zeros(2, bool), spec, np.random.default_rng(0))
    p.yaw_deg[:] = [range_deg, -range_deg]  # the largest turns, both ways
    images = FastAugmenter(cache, spec).images(np.arange(2), p)
    x = to_input_tensor(images, contract)  # what the network gets: edges repeated from column b inward
    for k in range(2):
        inside = x[k, :, b:-b, 0]
        assert np.all(np.diff(inside, axis=1) > 0), (range_deg, k)  # the ramp intact on every row: no edge left
        assert np.all(x[k, :, :b] == x[k, :, b:b + 1]) and np.all(x[k, :, -b:] == x[k, :, -b - 1:-b])
    unturned = to_input_tensor(cache.frames[0, :1], contract)
    assert np.all(unturned[0, :, :b] == unturned[0, :, b:b + 1])  # served frames are blanked alike


# ---- the moved camera (DAVE-2's "shifts"): the car moved sideways, labelled to aim back at the driver's line ----

def test_moved_camera_label_aims_back_and_is_the_side_cameras_at_their_offset() -> None:
    steering = np.linspace(-0.9, 0.9, 37)
    left, right = augment.LEFT, augment.RIGHT
    for x, camera in ((0.95, right), (-0.95, left)):  # moved right: what the right camera sees, Eq. 5; left: Eq. 4
        moved = augment.offset_label(steering, x, 10.0)
        side = augment.perspective_label(steering, np.full(37, camera), AugmentSpec().gamma)
        assert np.allclose(moved, side, atol=1e-12, rtol=0)
        assert np.array_equal(moved.astype(np.float32), side.astype(np.float32))
    assert np.all(augment.offset_label(steering, 1.0, 10.0) < steering)  # moved right: steer left
    assert np.all(augment.offset_label(steering, -1.0, 10.0) > steering)
    theta = np.radians(25 * 0.3)
    assert augment.offset_label(0.3, 2.0, 8.0) == pytest.approx(math.degrees(math.atan(math.tan(theta) - 0.25)) / 25)
    # through the draws: centre-camera samples only, mirrored by the flip
    spec = AugmentSpec(**{**NONE, "perspective": 0.5, "flip": 0.5, "offset_aug": 1.0, "offset_range": 2.0})
    p = draw_params(np.full(400, 0.2), np.ones(400, bool), spec, np.random.default_rng(1))
    centre = p.camera == augment.CENTER
    assert np.array_equal(p.moved, centre) and np.all(p.offset_m[~centre] == 0) and np.ptp(p.offset_m) > 3.5
    assert np.abs(p.offset_m).max() <= 2.0
    unflipped = augment.perspective_label(np.full(400, 0.2), p.camera, spec.gamma)
    unflipped = np.where(centre, augment.offset_label(0.2, p.offset_m, 10.0), unflipped)
    assert np.allclose(p.steering, np.where(p.flip, -unflipped, unflipped), atol=1e-6)


def test_moved_camera_draws_last_and_only_when_used() -> None:
    steering = np.random.default_rng(0).uniform(-0.5, 0.5, 300)
    for base in (AugmentSpec(), replace(AugmentSpec(), yaw_aug=0.5)):
        a = draw_params(steering, np.ones(300, bool), base, np.random.default_rng(2))
        b = draw_params(steering, np.ones(300, bool), replace(base, offset_range=1.0), np.random.default_rng(2))
        c = draw_params(steering, np.ones(300, bool), replace(base, offset_aug=0.5), np.random.default_rng(2))
        assert a.offset is None and np.array_equal(a.steering, b.steering)
        assert c.moved.any() and not np.array_equal(a.steering, c.steering)
        for name in ("camera", "shadow_xy", "beta", "flip", "pan_xy", "tilt_deg", "shift_px", "yaw_deg"):
            x, y = getattr(a, name), getattr(c, name)
            assert (x is None and y is None) or np.array_equal(x, y), name  # the draws before it are unchanged
        assert np.array_equal(a.steering[~c.moved], c.steering[~c.moved])


def test_moved_camera_edge_pull_sees_the_moved_camera() -> None:
    spec = AugmentSpec(**{**NONE, "offset_aug": 1.0, "edge_gain": 0.2, "edge_margin": 1.0})
    middles = np.linspace(-3, 3, 200)
    p = draw_params(np.zeros(200), np.zeros(200, bool), spec, np.random.default_rng(3), middles)
    middle = middles - p.offset_m  # moved right by x: the middle lies x further left
    pull = 0.2 * np.sign(middle) * np.maximum(0.0, np.abs(middle) - 1.0)
    assert np.allclose(p.steering, np.clip(augment.offset_label(0.0, p.offset_m, 10.0) + pull, -1, 1), atol=1e-6)


def _road(lines_m: tuple[float, ...], half_width_m: float = 0.12) -> np.ndarray:
    """A flat road seen by the real camera: white lines ``lines_m`` metres to the right (+) on grey, sky above."""
    from protocol import camera

    k_inv = np.linalg.inv(camera.intrinsics(320, 160))
    xs, ys = np.meshgrid(np.arange(320.0), np.arange(160.0))
    rays = camera.pitch_matrix(camera.PITCH_DEG).T @ k_inv @ np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    with np.errstate(divide="ignore", invalid="ignore"):
        ground_x = np.where(rays[1] > 0, camera.HEIGHT_M * rays[0] / rays[1], np.nan).reshape(160, 320)
    img = np.full((160, 320, 3), 90, np.uint8)
    img[np.isnan(ground_x)] = (120, 170, 230)
    for line in lines_m:
        img[np.abs(ground_x - line) < half_width_m] = 255
    return img


def _line_columns(img: np.ndarray, row: int) -> np.ndarray:
    """Centre column of each white run on ``row``."""
    white = img[row, :, 0] > 200
    edges = np.flatnonzero(np.diff(np.r_[0, white.astype(np.int8), 0]))
    return (edges[0::2] + edges[1::2] - 1) / 2


@pytest.mark.parametrize("x", [0.0, 0.95, -1.5, 2.0])
def test_moved_camera_moves_the_road_as_the_camera_geometry_says(x: float) -> None:
    from tools.drivelog.camera import ViewSynthesizer

    spec = AugmentSpec()
    for line in (-3.5, -1.75, 0.0, 1.75, 3.5):  # one at a time: each line where the recorded frame shows it
        recorded, expected = _road((line,)), _road((line - x,))  # the camera x to the right: the line x further left
        moved = reference.move(recorded, x, spec)
        for row in range(80, 136, 5):
            seen, got, want = _line_columns(recorded, row), _line_columns(moved, row), _line_columns(expected, row)
            if len(seen) == 1 and 3 < seen[0] < 316 and len(want) == 1:
                assert len(got) == 1 and abs(got[0] - want[0]) <= 1.0, (x, line, row, got, want)
    recorded = _road((-3.5, -1.75, 0.0, 1.75, 3.5))
    moved = reference.move(recorded, x, spec)
    assert np.array_equal(moved[:66], recorded[:66])  # the sky stays
    assert np.array_equal(moved[137:], recorded[137:])  # the bonnet travels with the camera
    assert np.array_equal(moved, ViewSynthesizer().view(recorded, x, 0.0))  # the closed loop's view synthesis
    if x == 0.0:
        assert np.array_equal(moved, recorded)


def test_moved_camera_fast_path_is_the_reference() -> None:
    """The batched path (network size, composed with flips and turns) against the literal one on a road image."""
    from drive_server.serving.contract import PAPER_CONTRACT
    from drive_server.serving.preprocess import frame_to_network_image

    road = _road((-3.5, -1.75, 0.0, 1.75, 3.5), half_width_m=0.3)
    net = frame_to_network_image(road, PAPER_CONTRACT)
    cache = FrameCache(np.broadcast_to(net, (3, 1, *net.shape)).copy(), CAMERAS, PAPER_CONTRACT, np.ones(1, bool), [])
    spec = AugmentSpec(**{**NONE, "flip": 0.5, "shadow": 0.5, "offset_aug": 1.0, "yaw_aug": 0.5})
    p = draw_params(np.zeros(16), np.zeros(16, bool), spec, np.random.default_rng(4))
    p.offset_m[0], p.flip[0], p.shadow[0], p.yaw[0], p.yaw_deg[0] = 0.0, False, False, False, 0.0
    fast = FastAugmenter(cache, spec).images(np.zeros(16, np.int64), p)
    assert np.abs(fast[0].astype(int) - net).max() <= 1  # not moved at all: the cached frame
    for k in range(16):
        full, label = reference.augment_reference({c: road for c in CAMERAS}, p, k, spec)
        ref = frame_to_network_image(full, PAPER_CONTRACT).astype(np.int16)
        assert label == p.steering[k]
        assert np.abs(ref - fast[k]).mean() < 4.0, (k, np.abs(ref - fast[k]).mean())
