"""A world built with ``keep_albedo=False`` (the environment's own, without cones) gives its albedo back as it is
lit: the same textures, and a process with one environment peaks at its lit texture, not the albedo beside it."""

from __future__ import annotations

import sys
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import numpy as np
import pytest

from tests.test_render import stadium
from tools.sim.render import world as render_world


def test_a_world_that_lets_its_albedo_go_has_the_same_textures():
    track = stadium(trees=40)
    render_world.clear_caches()
    kept = render_world.World(track, 5.0)
    assert track.digest in render_world._albedo_cache
    render_world.clear_caches()
    let_go = render_world.World(track, 5.0, keep_albedo=False)
    assert track.digest not in render_world._albedo_cache  # painted again for another sun, never read zeroed
    assert len(kept.ground.mips) == len(let_go.ground.mips)
    for a, b in zip(kept.ground.mips, let_go.ground.mips, strict=True):
        assert np.array_equal(a, b)
    assert kept.ground.border == let_go.ground.border
    for name, visibility in kept.sun_visibility.items():
        assert np.array_equal(visibility, let_go.sun_visibility[name])
    render_world.clear_caches()


def _peak_mb_of_one_env() -> float:
    """The process's own peak (VmHWM: getrusage's maxrss keeps the parent's from before the exec), less the pages
    of files it maps (the libraries: 45-85 MB, depending on how the kernel faults in a freshly installed .so), so
    that what is measured is the memory the environment itself allocates."""
    from pathlib import Path

    from tools.envs import DriveEnv

    DriveEnv(track="lake").close()
    status = {line.split(":")[0]: int(line.split()[1]) for line in Path("/proc/self/status").read_text().splitlines()
              if line.startswith(("VmHWM:", "RssFile:"))}
    return (status["VmHWM"] - status["RssFile"]) / 1024


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the albedo's pages go back with Linux's madvise")
def test_one_env_process_peaks_below_its_texture_and_albedo_together():
    """Was: about 430 MB of its own (474 MB with the libraries' pages), the lake's 128 MB albedo, its 227 MB lit
    texture with mips and the lighting's temporaries at once (measured here: about 260 MB of its own)."""
    pytest.importorskip("gymnasium")
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        peak = pool.submit(_peak_mb_of_one_env).result()
    assert peak < 290, peak


@pytest.mark.parametrize(("shadow_shape", "band"), [((520, 180), 256), ((500, 170), 96), ((520, 180), 33)])
def test_a_consumed_albedo_is_lit_into_the_same_bytes(monkeypatch, shadow_shape, band):
    """Band by band from the shadow rows each band reads (a shadow map of half the size, even bands), or from the
    whole maps (any other size): the bytes of the whole-texture computation, the albedo given back as it goes."""
    import cv2

    from tests.test_render_fast_paths import _light_ground_before
    from tools.sim.render.texture import GroundAlbedo

    rng = np.random.default_rng(4)
    rgb = rng.integers(0, 256, (1040, 360, 3), np.uint8)
    shadow = cv2.GaussianBlur(rng.integers(0, 256, shadow_shape, np.uint8), (0, 0), 1.2)
    before = _light_ground_before(GroundAlbedo(rgb, 0.0, 0.0, 0.05, (90, 120, 60), np.zeros((130, 45), np.uint8)),
                                  shadow, render_world.AMBIENT, 0.55)
    monkeypatch.setattr(render_world, "LIGHT_BAND_ROWS", band)
    albedo = GroundAlbedo(rgb.copy(), 0.0, 0.0, 0.05, (90, 120, 60), np.zeros((130, 45), np.uint8))
    lit = render_world.light_ground(albedo, shadow, render_world.AMBIENT, 0.55, consume=True)
    assert np.array_equal(lit.mips[0], before)
    assert np.array_equal(lit.mips[1], cv2.pyrDown(before))
