"""The renderer's fast paths draw the very bytes of the plain computations they replaced (bonnet, rails)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from tools.sim.render.bonnet import blend_bonnet, bonnet_layer, draw_bonnet
from tools.sim.render.camera import fog_weight
from tools.sim.render.renderer import Renderer
from tools.sim.render.sprites import NEAR, RAIL_CULL_MARGIN, SHIFT, _runs
from tools.sim.render.world import Pose, get_world
from tools.sim.track.files import get_track


@pytest.mark.parametrize("lateral", [0.0, 0.95, -0.95, 0.69])
def test_the_bonnet_blends_only_its_edge_and_draws_the_same_bytes(lateral):
    layer = bonnet_layer(lateral)
    rng = np.random.default_rng(7)
    for light in (1.0, 0.45, 1.8, 0.1, 1.3, 0.97):
        frame = rng.integers(0, 256, (160, 320, 3), np.uint8)
        assert np.array_equal(draw_bonnet(frame.copy(), layer, light), blend_bonnet(frame.copy(), layer, light))
    assert 0 < len(layer.edge[0]) <= 320 * 2  # about one blended pixel per column


def _rails_before(painter, fb, cam, pos, axes, intensity, haze):
    """``PropPainter._draw_rails`` as it was: one projection per rail height, its colour lit every frame."""
    up = axes[:, 2]
    reach = painter.view_dist + RAIL_CULL_MARGIN
    for rail, top, lit, centre, radius in painter.rails:
        if math.hypot(pos[0] - centre[0], pos[1] - centre[1]) > radius + reach:
            continue
        cam_xyz = (rail - pos[:2]) @ axes[:, :2].T - pos[2] * up
        front = cam_xyz[:, 2] > NEAR
        if front.sum() < 2:
            continue
        dist = float(np.median(np.hypot(cam_xyz[front, 0], cam_xyz[front, 2])))
        if dist > painter.view_dist:
            continue
        fog = float(fog_weight(dist, painter.fog_density))
        rgb = lit[:3] * (1 + (intensity - 1) / 255 * lit[3])
        color = (rgb * (1 - fog) + haze * fog).tolist()
        for zh, width in ((top, 2), (0.5 * top, 1)):
            pts = cam_xyz + zh * up
            for run in _runs(front):
                px = np.round(cam.project(pts[run]) * (1 << SHIFT)).astype(np.int32)
                cv2.polylines(fb, [px], False, color, width, cv2.LINE_AA, SHIFT)
        tops = np.round(cam.project(cam_xyz[front] + top * up) * (1 << SHIFT)).astype(np.int32)
        feet = np.round(cam.project(cam_xyz[front]) * (1 << SHIFT)).astype(np.int32)
        cv2.polylines(fb, list(np.stack([feet, tops], 1)), False, color, 1, cv2.LINE_AA, SHIFT)


def test_the_bridge_rails_are_drawn_as_before():
    track = get_track("lake")
    renderer = Renderer(get_world(track, 0.0, None))
    painter = renderer.props
    assert painter.rails, "lake has a bridge"
    centre = painter.rails[0][3]
    s = track.project(float(centre[0]), float(centre[1])).s
    drawn = 0
    for ahead in np.linspace(-140.0, 20.0, 24):  # approaching the bridge, on it, and just past it
        x, y, heading = track.point_at((s + ahead) % track.length)
        for name, state in renderer.cameras.items():
            m = state.model
            c, sn = math.cos(heading), math.sin(heading)
            axes = m.axes @ np.array([[c, sn, 0.0], [-sn, c, 0.0], [0.0, 0.0, 1.0]])
            pos = np.array([x + c * m.forward - sn * m.lateral, y + sn * m.forward + c * m.lateral, m.height])
            for intensity in (1.0, 0.6):
                haze = painter.haze[:3] * (1 + (intensity - 1) * painter.haze[3] / 255)
                now, before = np.full((160, 320, 3), 90, np.uint8), np.full((160, 320, 3), 90, np.uint8)
                painter._draw_rails(now, m, pos, axes, intensity, haze)
                _rails_before(painter, before, m, pos, axes, intensity, haze)
                assert np.array_equal(now, before), (ahead, name, intensity)
                drawn += int((now != 90).any())
    assert drawn > 20  # the rails were in view, not skipped


def test_a_frame_with_the_bridge_and_the_bonnet_is_deterministic():
    track = get_track("lake")
    renderer = Renderer(get_world(track, 0.0, None))
    centre = renderer.props.rails[0][3]
    x, y, heading = track.point_at(track.project(float(centre[0]), float(centre[1])).s - 30.0)
    frames = [renderer.render(Pose(x, y, heading), light_intensity=light) for light in (1.0, 1.0, 0.5)]
    assert np.array_equal(frames[0], frames[1]) and not np.array_equal(frames[0], frames[2])


def _light_ground_before(albedo, shadow, ambient, direct):
    """``light_ground`` as it was: the full-size light, share and lit textures at once (300 MB more for the lake)."""
    visible = 1.0 - shadow.astype(np.float32) / 255.0
    light = ambient + direct * visible
    share = direct * visible / light
    h, w = albedo.shape
    light8 = cv2.resize(np.clip(light * 128.0, 0, 255).astype(np.uint8), (w, h), interpolation=cv2.INTER_LINEAR)
    share8 = cv2.resize(np.round(share * 255.0).astype(np.uint8), (w, h), interpolation=cv2.INTER_LINEAR)
    lit = cv2.multiply(albedo.rgb, cv2.cvtColor(light8, cv2.COLOR_GRAY2RGB), scale=1.0 / 128.0)
    rgba = cv2.cvtColor(lit, cv2.COLOR_RGB2RGBA)
    cv2.mixChannels([share8], [rgba], [0, 3])
    return rgba


@pytest.mark.parametrize("band", [512, 96, 34])
def test_the_ground_is_lit_band_by_band_into_the_same_bytes(monkeypatch, band):
    """Was: the lake's world peaked at 760 MB while it was built, its full-size temporaries beside the texture."""
    from tools.sim.render import world
    from tools.sim.render.texture import GroundAlbedo

    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, (1040, 360, 3), np.uint8)
    shadow = cv2.GaussianBlur(rng.integers(0, 256, (520, 180), np.uint8), (0, 0), 1.2)
    albedo = GroundAlbedo(rgb=rgb, x0=0.0, y1=0.0, res=0.05, mean_rgb=(90, 120, 60),
                          water=np.zeros((130, 45), np.uint8))
    monkeypatch.setattr(world, "LIGHT_BAND_ROWS", band)
    lit = world.light_ground(albedo, shadow, world.AMBIENT, 0.55)
    before = _light_ground_before(albedo, shadow, world.AMBIENT, 0.55)
    assert np.array_equal(lit.mips[0], before)
    assert all(np.array_equal(a, b) for a, b in zip(lit.mips[1:], [cv2.pyrDown(before)], strict=False))


def test_upsampled_rows_are_the_rows_of_the_whole_resize():
    from tools.sim.render.world import _upsampled_rows

    low = np.random.default_rng(5).integers(0, 256, (37, 23), np.uint8)
    whole = cv2.resize(low, (46, 74), interpolation=cv2.INTER_LINEAR)
    for top, bottom in [(0, 74), (0, 2), (2, 8), (10, 40), (40, 74), (72, 74), (0, 10), (64, 74)]:
        assert np.array_equal(_upsampled_rows(low, (46, 74), top, bottom), whole[top:bottom]), (top, bottom)
    other = cv2.resize(low, (50, 81), interpolation=cv2.INTER_LINEAR)  # not twice the size: the whole resize
    assert np.array_equal(_upsampled_rows(low, (50, 81), 7, 30), other[7:30])


def test_the_grain_is_added_band_by_band_into_the_same_bytes():
    from tools.sim.render.texture import add_grain

    rng = np.random.default_rng(11)
    img = rng.integers(0, 256, (1100, 700, 3), np.uint8)
    tile = rng.integers(0, 65, (512, 512, 3), np.uint8)
    for strength in (1.0, 0.6, 1.7):
        whole = cv2.repeat(tile, 1100 // 512 + 1, 700 // 512 + 1)[:1100, :700]
        expected = cv2.addWeighted(img, 1.0, whole, strength, -32.0 * strength)
        banded = img.copy()
        add_grain(banded, tile, strength)
        assert np.array_equal(banded, expected), strength
