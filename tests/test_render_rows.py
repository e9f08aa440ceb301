"""``Renderer.render(rows=...)`` draws the wanted rows only, and they are the whole frame's very bytes; the
environment's ``observation="model"`` without the JPEG uses it and observes what the whole frame gives."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tests.test_render import stadium
from tools.sim.render.renderer import Renderer
from tools.sim.render.world import Pose, World
from tools.sim.track.looks import Appearance, FrameJitter

ROWS = [(64, 136), (0, 40), (60, 75), (130, 160), (100, 101), (0, 160)]


@pytest.fixture(scope="module")
def processed() -> World:
    """Trees, and the camera's processing: tone, a 5x5 blur (it reads two rows beyond each), noise."""
    look = Appearance(exposure_ev=0.2, contrast=1.1, blur=1.2, noise=3.0, jitter=FrameJitter(noise=1.0))
    return World(replace(stadium(trees=60), appearance=look))


@pytest.mark.parametrize("rig", ["unity", "classic"])
def test_the_wanted_rows_are_the_whole_frames_bytes(processed: World, rig: str):
    """Was: every frame drew all 160 rows' sky and ground, where the 64x64 model input reads rows 64-136."""
    plain = World(stadium(trees=60))
    for world in (plain, processed):
        renderer = Renderer(world, seed=3, rig=rig)
        for i, x in enumerate(np.linspace(-20.0, 150.0, 6)):
            pose = Pose(float(x), -40.0 + 0.5 * i, 0.05 * i)
            for camera, light, tilt in (("center", 1.0, (0.0, 0.0)), ("left", 0.6, (0.0, 0.0)),
                                        ("right", 1.4, (0.4, -0.3))):
                for top, bottom in ROWS:
                    renderer.render(Pose(pose.x + 30.0, pose.y, pose.yaw + 1.0), "center")  # other rows in scratch
                    state = renderer.postfx.rng.bit_generator.state  # the per-frame jitter's draws, the same
                    whole = renderer.render(pose, camera, light, *tilt)
                    renderer.postfx.rng.bit_generator.state = state
                    part = renderer.render(pose, camera, light, *tilt, rows=(top, bottom))
                    assert part.shape == whole.shape
                    assert np.array_equal(part[top:bottom], whole[top:bottom]), (world, x, camera, top, bottom)


def test_rows_outside_the_frame_are_refused(processed: World):
    renderer = Renderer(processed)
    for rows in ((-1, 10), (10, 10), (50, 161)):
        with pytest.raises(ValueError, match="rows must be"):
            renderer.render(Pose(0.0, -40.0, 0.0), rows=rows)


def test_the_model_input_without_the_jpeg_is_the_whole_frames():
    """observation="model", jpeg=False renders the contract's rows only; the observation is the one the whole
    frame gives (the same env with render_mode="rgb_array" renders whole frames, for render())."""
    gym = pytest.importorskip("gymnasium")
    import tools.envs  # noqa: F401

    cut = gym.make("rbc/Drive-v0", track="lake", observation="model", jpeg=False, cameras=3)
    whole = gym.make("rbc/Drive-v0", track="lake", observation="model", jpeg=False, cameras=3,
                     render_mode="rgb_array")
    assert cut.unwrapped._rows == (64, 136) and whole.unwrapped._rows is None
    a, info = cut.reset(seed=5)
    b, _ = whole.reset(seed=5)
    for step in range(40):
        for name in ("center", "left", "right"):
            assert a[name].shape == (64, 64, 3) and a[name].dtype == np.uint8
            assert np.array_equal(a[name], b[name]), (step, name)
        action = info["expert_action"]
        a, _, _, _, info = cut.step(action)
        b, _, _, _, _ = whole.step(action)
    cut.close()
    whole.close()


def test_the_renderers_of_a_world_share_its_tables_while_it_lives():
    """Was: every episode's renderer made its own camera tables and sky (7 MB a reset, kept by the heap)."""
    import gc
    import weakref

    from tools.sim.render.renderer import _WORLD_TABLES

    world = World(stadium(trees=20))
    first, second = Renderer(world, seed=1), Renderer(world, seed=1)
    pose = Pose(30.0, -40.0, 0.1)
    assert np.array_equal(first.render(pose, "left", 0.7), second.render(pose, "left", 0.7))
    assert list(first._states) == ["left"]  # a camera's tables are made for its first frame
    assert first.cameras is second.cameras and first._sky is second._sky
    assert Renderer(world, rig="classic").cameras is not first.cameras  # per rig
    alive, tables = weakref.ref(world), len(_WORLD_TABLES)
    del world, first, second
    gc.collect()
    assert alive() is None and len(_WORLD_TABLES) == tables - 1  # the shared tables keep no world alive
