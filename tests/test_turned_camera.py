"""The turned-camera augmentation (not in the paper): its label, its geometry, and the edge it must not leave."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from drive_server.preprocess import to_input_tensor
from models.augmentation import augment, geometry
from models.augmentation.augment import CAMERAS, AugmentSpec, draw_params
from models.augmentation.fastaug import FastAugmenter
from models.data.framecache import FrameCache

NONE = dict(perspective=0.0, shadow=0.0, brightness=0.0, flip=0.0, pan=0.0, tilt=0.0)


def test_turned_camera_label_steers_back_and_flip_mirrors_it() -> None:
    spec = AugmentSpec(**{**NONE, "yaw": 1.0, "yaw_range_deg": 6.0, "yaw_gain": 0.5})
    steering = np.full(400, 0.2)
    p = draw_params(steering, np.zeros(400, bool), replace(spec, flip=0.5), np.random.default_rng(1))
    assert p.turned.all() and np.abs(p.yaw_deg).max() <= 6.0 and np.ptp(p.yaw_deg) > 10
    unflipped = 0.2 - 0.5 * p.yaw_deg / 25  # turned right (+): steer left, half the turn at once
    expect = np.where(p.flip, -unflipped, unflipped)
    assert np.allclose(p.steering, expect, atol=1e-6)
    # without it the generator is consumed exactly as before the augmentation existed
    a = draw_params(steering, np.ones(400, bool), AugmentSpec(), np.random.default_rng(2))
    b = draw_params(steering, np.ones(400, bool), replace(AugmentSpec(), yaw_range_deg=3.0), np.random.default_rng(2))
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
    right = augment.turn(img, 4.0, spec)
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
