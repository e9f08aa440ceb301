"""The six augmentations: label rules, Table 5 probabilities, Eq. 11 crops, and fast path vs literal reference."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drive_server.serving.contract import NVIDIA_CONTRACT, PAPER_CONTRACT
from drive_server.serving.preprocess import frame_to_network_image
from models.augmentation import augment, geometry, reference
from models.augmentation.augment import CENTER, LEFT, RIGHT, AugmentSpec, draw_params
from models.augmentation.fastaug import FastAugmenter, augment_batch
from models.augmentation.reference import augment_reference
from models.data.behavior import BEHAVIOR_SPECS, NVIDIA_AUGMENT, Behavior
from models.data.framecache import FrameCache, build_cache, load_frame
from protocol.datalog import read_log
from protocol.facts import CAMERAS

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
NONE = dict(perspective=0.0, shadow=0.0, brightness=0.0, flip=0.0, pan=0.0, tilt=0.0)
GAMMA = 0.95 / 10


# ---- label rules ----

@pytest.mark.parametrize("steering", [-1.0, -0.6, -0.2095149, 0.0, 0.05, 0.423, 0.9])
def test_perspective_labels_follow_eq_4_and_5(steering: float) -> None:
    theta = math.radians(25 * steering)
    t = math.tan(theta)
    delta = math.atan(GAMMA / (1 + t * t + GAMMA * t))  # Eq. 4
    phi = math.atan(GAMMA / (1 + t * t - GAMMA * t))  # Eq. 5
    left = augment.perspective_label(steering, LEFT, GAMMA)
    right = augment.perspective_label(steering, RIGHT, GAMMA)
    assert left == pytest.approx(max(-1, min(1, math.degrees(theta + delta) / 25)), abs=1e-12)
    assert right == pytest.approx(max(-1, min(1, math.degrees(theta - phi) / 25)), abs=1e-12)
    # geometry: aim at the point d ahead seen from x to the side; left camera steers right (positive)
    if abs(left) < 1:
        assert math.tan(math.radians(25 * left)) == pytest.approx(t + GAMMA)
    if abs(right) < 1:
        assert math.tan(math.radians(25 * right)) == pytest.approx(t - GAMMA)
    assert left >= steering >= right and left > right
    assert augment.perspective_label(steering, CENTER, GAMMA) == pytest.approx(steering)


def test_perspective_label_of_straight_driving_and_clamp() -> None:
    assert augment.perspective_label(0.0, LEFT, GAMMA) == pytest.approx(math.degrees(math.atan(GAMMA)) / 25)
    assert augment.perspective_label(0.0, RIGHT, GAMMA) == pytest.approx(-0.217072, abs=1e-6)
    assert augment.perspective_label(1.0, LEFT, GAMMA) == 1.0
    assert augment.perspective_label(-1.0, RIGHT, GAMMA) == -1.0


def test_flip_negates_label_and_mirrors_eq_7() -> None:
    img = np.random.default_rng(0).integers(0, 256, (160, 320, 3), dtype=np.uint8)
    out, label = reference.flip(img, 0.3)
    assert label == -0.3
    assert np.array_equal(out[:, 0], img[:, 319]) and np.array_equal(out[:, 319 - 5], img[:, 5])
    spec = AugmentSpec(**{**NONE, "flip": 1.0})
    p = draw_params(np.array([0.3, -0.7, 0.0]), np.ones(3, bool), spec, np.random.default_rng(0))
    assert p.flip.all() and np.allclose(p.steering, [-0.3, 0.7, 0.0]) and not np.signbit(p.steering[2])


def test_flip_is_for_centre_frames_only() -> None:
    spec = AugmentSpec(**{**NONE, "perspective": 1.0, "flip": 1.0})
    p = draw_params(np.full(2000, 0.1), np.ones(2000, bool), spec, np.random.default_rng(0))
    assert (p.camera != CENTER).all() and not p.flip.any()
    expected = np.where(p.camera == LEFT, augment.perspective_label(0.1, LEFT, GAMMA),
                        augment.perspective_label(0.1, RIGHT, GAMMA))
    assert np.allclose(p.steering, expected, atol=1e-6)


@pytest.mark.parametrize("behavior", list(Behavior))
def test_table_5_probabilities(behavior: Behavior) -> None:
    spec = BEHAVIOR_SPECS[behavior].augment
    n = 40000
    p = draw_params(np.zeros(n), np.ones(n, bool), spec, np.random.default_rng(1))
    expected = {"simplistic": (0.5, 0.5), "rigorous": (0.5, 0.0), "collision": (0.0, 0.5)}[behavior.value]
    assert (p.camera == LEFT).mean() == pytest.approx(expected[0] / 2, abs=0.01)
    assert (p.camera == RIGHT).mean() == pytest.approx(expected[0] / 2, abs=0.01)
    centre = p.camera == CENTER
    assert p.flip[centre].mean() == pytest.approx(expected[1], abs=0.015)
    for name, prob in (("shadow", 0.3), ("brightness", 0.4), ("pan", 0.1), ("tilt", 0.05)):
        assert getattr(p, name).mean() == pytest.approx(prob, abs=0.01), name
    assert np.abs(p.beta).max() <= 100 and np.abs(p.tilt_deg).max() <= 1
    assert (np.abs(p.pan_xy) <= [16, 8]).all()
    xy = p.shadow_xy
    assert xy.shape[1:] == (4, 4, 2) and xy[..., 0].min() >= 0 and xy[..., 0].max() <= 320
    assert xy[..., 1].min() >= 80 and xy[..., 1].max() <= 160


def test_one_camera_samples_never_use_side_frames() -> None:
    p = draw_params(np.zeros(500), np.zeros(500, bool), BEHAVIOR_SPECS[Behavior.SIMPLISTIC].augment,
                    np.random.default_rng(0))
    assert (p.camera == CENTER).all()


def test_draws_are_seeded() -> None:
    spec = BEHAVIOR_SPECS[Behavior.SIMPLISTIC].augment
    a = draw_params(np.zeros(64), np.ones(64, bool), spec, np.random.default_rng(5))
    b = draw_params(np.zeros(64), np.ones(64, bool), spec, np.random.default_rng(5))
    c = draw_params(np.zeros(64), np.ones(64, bool), spec, np.random.default_rng(6))
    assert all(np.array_equal(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    assert not np.array_equal(a.camera, c.camera)


# ---- pixel rules ----

def test_brightness_is_eq_6() -> None:
    img = np.array([[[0, 100, 250]]], np.uint8)
    assert reference.brightness(img, 10.4).tolist() == [[[10, 110, 255]]]
    assert reference.brightness(img, -100).tolist() == [[[0, 0, 150]]]


def test_shadows_darken_the_quadrilaterals_only() -> None:
    img = np.full((160, 320, 3), 200, np.uint8)
    quad = np.array([[[10, 90], [100, 90], [100, 150], [10, 150]]] * 4)
    out = reference.shadows(img, quad, 0.65)
    assert out[120, 50].tolist() == [130, 130, 130] and out[40, 200].tolist() == [200, 200, 200]


def test_tilt_crop_is_eq_11() -> None:
    w, h, deg = 320, 160, 1.0
    a = math.radians(deg)
    w_roi, h_roi = geometry.max_inscribed_rect(w, h, deg)  # fully constrained for small angles
    assert w_roi == pytest.approx((w * math.cos(a) - h * math.sin(a)) / math.cos(2 * a))
    assert h_roi == pytest.approx((h * math.cos(a) - w * math.sin(a)) / math.cos(2 * a))
    hw, hh = geometry.max_inscribed_rect(320, 20, 30.0)  # half constrained: a thin frame rotated a lot
    assert (hw, hh) == pytest.approx((20 / (2 * math.sin(math.radians(30))), 20 / (2 * math.cos(math.radians(30)))))
    assert geometry.max_inscribed_rect(w, h, 0.0) == (w, h)
    assert geometry.max_inscribed_rect(w, h, -deg) == (w_roi, h_roi)
    # the ROI's corners lie inside the rotated frame
    corners = np.array([[w / 2 + sx * w_roi / 2, h / 2 + sy * h_roi / 2] for sx in (-1, 1) for sy in (-1, 1)])
    back = geometry.apply_points(np.linalg.inv(np.vstack([geometry.rotation_matrix(w, h, deg), [0, 0, 1]])),
                                 corners)
    assert (back >= -1e-6).all() and (back[:, 0] <= w + 1e-6).all() and (back[:, 1] <= h + 1e-6).all()


@pytest.mark.parametrize("deg", [-1.0, -0.37, 0.5, 1.0])
def test_tilt_leaves_no_black_corners(deg: float) -> None:
    white = np.full((160, 320, 3), 255, np.uint8)
    out = reference.tilt(white, deg)
    assert out.shape == white.shape
    assert out.min() == 255  # corners included: nothing of the null area is left


@pytest.mark.parametrize(("tx", "ty"), [(16.0, 8.0), (-16.0, -8.0), (3.3, -0.2), (-0.01, 7.99)])
def test_pan_leaves_no_null_area(tx: float, ty: float) -> None:
    white = np.full((160, 320, 3), 255, np.uint8)
    assert reference.pan(white, tx, ty).min() == 255


# ---- fast path ----

def _white_cache(contract=PAPER_CONTRACT) -> FrameCache:
    frames = np.full((3, 4, contract.height, contract.width, 3), 255, np.uint8)
    return FrameCache(frames, CAMERAS, contract, np.ones(4, bool), [])


def test_fast_geometric_warps_leave_no_null_area() -> None:
    spec = AugmentSpec(**{**NONE, "pan": 1.0, "tilt": 1.0, "flip": 0.5})
    p = draw_params(np.zeros(200), np.ones(200, bool), spec, np.random.default_rng(0))
    p.pan_xy[:2] = [[16, 8], [-16, -8]]
    p.tilt_deg[:2] = [1.0, -1.0]
    out = FastAugmenter(_white_cache(), spec).images(np.arange(200) % 4, p)
    assert out.min() == 255


@pytest.fixture(scope="module")
def real() -> tuple[list, FrameCache]:
    samples, _ = read_log(SAMPLE)
    # full-size decode so that only the augmentation path differs from the reference
    return samples, build_cache(samples, PAPER_CONTRACT, reduce=1, workers=1)


def _compare(real, spec: AugmentSpec, seed: int = 3) -> tuple[float, float]:
    """Mean |fast - reference| and mean |unaugmented - reference| over the 36 real frames (0..255)."""
    samples, cache = real
    n = len(samples)
    steering = np.array([s.steering for s in samples])
    p = draw_params(steering, np.ones(n, bool), spec, np.random.default_rng(seed))
    fast = FastAugmenter(cache, spec).images(np.arange(n), p)
    diff, base = [], []
    for k, s in enumerate(samples):
        frames = {c: load_frame(getattr(s, c)) for c in CAMERAS}
        full, label = augment_reference(frames, p, k, spec)
        assert label == p.steering[k]
        ref = frame_to_network_image(full, PAPER_CONTRACT).astype(np.int16)
        diff.append(np.abs(ref - fast[k]).mean())
        base.append(np.abs(ref - cache.frames[0, k]).mean())
    return float(np.mean(diff)), float(np.mean(base))


@pytest.mark.parametrize(("override", "bound"), [
    ({"perspective": 1.0}, 0.01), ({"flip": 1.0}, 0.01),  # exact: another cached frame, a mirror
    ({"flip": 1.0, "shadow": 1.0}, 2.5), ({"shadow": 1.0, "brightness": 1.0}, 3.0),
    ({"shadow": 1.0}, 2.5), ({"brightness": 1.0}, 2.0),  # edges of shadows, clamping inside resize windows
    ({"pan": 1.0}, 5.5), ({"tilt": 1.0}, 5.5),  # interpolation at 64x64 instead of 320x160
    ({"pan": 1.0, "tilt": 1.0, "flip": 1.0, "shadow": 1.0, "brightness": 1.0}, 6.5),
    ({"yaw_aug": 1.0}, 5.5), ({"yaw_aug": 1.0, "flip": 1.0, "shadow": 1.0, "perspective": 1.0}, 6.5),  # turned
    ({"offset_aug": 1.0}, 2.5), ({"offset_aug": 1.0, "yaw_aug": 1.0, "flip": 1.0, "shadow": 1.0, "tilt": 1.0}, 7.0),
])
def test_fast_path_agrees_with_literal_reference(real, override: dict, bound: float) -> None:
    diff, base = _compare(real, AugmentSpec(**{**NONE, **override}))
    assert diff < bound, (override, diff)
    if {"pan", "tilt", "yaw_aug", "offset_aug"} & set(override):
        assert diff < 0.5 * base  # far closer than a wrong geometry (no transform at all) would be


def test_fast_brightness_clamps_and_shadow_darkens() -> None:
    cache = _white_cache()
    spec = AugmentSpec(**{**NONE, "brightness": 1.0})
    p = draw_params(np.zeros(4), np.ones(4, bool), spec, np.random.default_rng(0))
    p.beta[:] = [50, -100, -20.4, 0]
    out = FastAugmenter(cache, spec).images(np.arange(4), p)
    assert [int(o.mean()) for o in out] == [255, 155, 235, 255]
    spec = AugmentSpec(**{**NONE, "shadow": 1.0})
    p = draw_params(np.zeros(1), np.ones(1, bool), spec, np.random.default_rng(0))
    p.shadow_xy[0] = [[0, 80], [320, 80], [320, 160], [0, 160]]  # the whole lower half
    out = FastAugmenter(cache, spec).images(np.arange(1), p)[0]
    assert out[50, 32].tolist() == [166, 166, 166] and out[10, 32].tolist() == [255, 255, 255]


def test_nvidia_yuv_brightness_moves_luma_only_and_shift_corrects_label() -> None:
    frames = np.zeros((1, 2, 66, 200, 3), np.uint8)
    frames[..., 0], frames[..., 1:] = 120, 100
    cache = FrameCache(frames, ("center",), NVIDIA_CONTRACT, np.ones(2, bool), [])
    spec = replace(NVIDIA_AUGMENT, brightness=1.0, shift=1.0, flip=0.0)
    p = draw_params(np.array([0.1, 0.1]), np.zeros(2, bool), spec, np.random.default_rng(0))
    out = FastAugmenter(cache, spec).images(np.arange(2), p)
    assert np.allclose(out[..., 1:], 100)
    assert np.allclose(out[:, 30, 100, 0], np.clip(120 + np.rint(p.beta), 0, 255))
    assert np.allclose(p.steering, np.clip(0.1 + 0.004 * p.shift_px, -1, 1), atol=1e-6)


def test_batches_are_float_nchw_in_the_contract_scale(real) -> None:
    samples, cache = real
    steering = np.array([s.steering for s in samples], np.float32)
    aug = FastAugmenter(cache, BEHAVIOR_SPECS[Behavior.SIMPLISTIC].augment)
    idx = np.arange(len(samples))
    x, y = augment_batch(aug, idx, steering, np.ones(len(samples), bool), np.random.default_rng(0))
    assert x.shape == (36, 3, 64, 64) and x.dtype == np.float32 and x.flags.c_contiguous
    assert x.min() >= -0.5 and x.max() <= 0.5 and y.shape == (36, 1)
    x2, _ = augment_batch(aug, idx, steering, np.ones(len(samples), bool), np.random.default_rng(0))
    assert np.array_equal(x, x2)
    plain = FastAugmenter(cache, AugmentSpec(**NONE))
    x0, y0 = augment_batch(plain, idx, steering, np.ones(len(samples), bool), np.random.default_rng(0))
    expected = cache.frames[0].transpose(0, 3, 1, 2).astype(np.float32) / 255 - 0.5
    assert np.allclose(x0, expected, atol=1e-6) and np.allclose(y0[:, 0], steering)


def test_batched_geometry_equals_the_per_sample_maps() -> None:
    rng = np.random.default_rng(4)
    tx, ty = rng.uniform(-16, 16, 20), rng.uniform(-8, 8, 20)
    tx[:3], ty[:3] = [0.0, 5.0, -3.0], [0.0, -2.0, 4.0]  # integer and zero shifts
    deg = np.concatenate([[0.0, 1.0, -1.0], rng.uniform(-1, 1, 17)])
    pans = geometry.pan_pullbacks(320, 160, tx, ty)
    tilts = geometry.tilt_pullbacks(320, 160, deg)
    for k in range(20):
        assert np.allclose(pans[k], geometry.pan_pullback(320, 160, tx[k], ty[k]))
        assert np.allclose(tilts[k], geometry.tilt_pullback(320, 160, deg[k]))
    w, h = geometry.max_inscribed_rects(320, 20, np.array([30.0, 1.0, 0.0]))
    for k, d in enumerate([30.0, 1.0, 0.0]):
        assert (w[k], h[k]) == pytest.approx(geometry.max_inscribed_rect(320, 20, d))


def test_fast_nvidia_pipeline_agrees_with_reference(real) -> None:
    samples, _ = real
    cache = build_cache(samples, NVIDIA_CONTRACT, ("center",), reduce=1, workers=1)
    spec = replace(NVIDIA_AUGMENT, brightness=0.5, shift=1.0, flip=0.5)
    steering = np.array([s.steering for s in samples])
    p = draw_params(steering, np.zeros(len(samples), bool), spec, np.random.default_rng(2))
    fast = FastAugmenter(cache, spec).images(np.arange(len(samples)), p)
    diffs = []
    for k, s in enumerate(samples):
        full, _ = augment_reference({"center": load_frame(s.center)}, p, k, spec)
        diffs.append(np.abs(frame_to_network_image(full, NVIDIA_CONTRACT).astype(np.int16) - fast[k]).mean())
    assert np.mean(diffs) < 4.0
