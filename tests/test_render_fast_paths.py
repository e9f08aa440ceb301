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
