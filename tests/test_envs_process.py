"""What a process running rbc/Drive-v0 holds: its imports, OpenCV's threads, and the world built once at make.

The figures (CPU ms per step, peak and shared memory, vector scaling) belong to ``rbc env-bench``; these tests pin
the behaviours behind them.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")

from protocol.errors import BadValue  # noqa: E402
from tools.envs import DriveEnv  # noqa: E402
from tools.sim.render import world as render_world  # noqa: E402
from tools.sim.track.files import get_track  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def test_importing_the_env_loads_no_onnxruntime():
    """Was: ``import tools.envs`` imported onnxruntime (through OnnxPolicy), about 20 MB in every env process."""
    code = "import sys, tools.envs; print(sorted(m for m in ('onnxruntime', 'torch') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


@pytest.fixture
def opencv_threads():
    before = cv2.getNumThreads()
    yield
    cv2.setNumThreads(before)


def test_the_env_runs_opencv_on_one_thread_unless_told(opencv_threads):
    """Was: every env process ran OpenCV on all the cores, so a vector env's processes fought over them."""
    cv2.setNumThreads(3)
    DriveEnv(track="lake").close()
    assert cv2.getNumThreads() == 1
    cv2.setNumThreads(3)
    DriveEnv(track="lake", threads=None).close()
    assert cv2.getNumThreads() == 3
    DriveEnv(track="lake", threads=2).close()
    assert cv2.getNumThreads() == 2
    for bad in (0, True, "2", 1.5):
        with pytest.raises(BadValue, match="threads must be"):
            DriveEnv(track="lake", threads=bad)


def test_make_builds_the_world_reset_finds_it_and_its_albedo_is_let_go(monkeypatch):
    """Was: the world was built at the first reset, in each worker of a vector env (none shared the parent's), and
    the track's 128 MB albedo stayed cached beside it."""
    built = []
    world_init = render_world.World.__init__

    def counting(self, *args, **kwargs):
        built.append(args)
        world_init(self, *args, **kwargs)

    monkeypatch.setattr(render_world.World, "__init__", counting)
    render_world.clear_caches()
    lake = get_track("lake")
    env = DriveEnv(track="lake")
    assert len(built) == 1  # at make
    assert lake.digest not in render_world._albedo_cache
    _, info = env.reset(seed=0)
    env.step(info["expert_action"])
    env.reset(seed=1)
    assert len(built) == 1  # the resets drive the world made at make
    env.close()
    coned = DriveEnv(track="lake", cones=3)  # each cone layout a world of its own, painted on the same albedo
    assert len(built) == 2 and lake.digest in render_world._albedo_cache
    coned.close()
    render_world.clear_caches()


def test_the_worlds_of_a_distribution_let_their_albedo_go():
    """Was: the last two generated worlds' albedos (up to 144 MB each) stayed cached beside their textures."""
    env = DriveEnv(worlds={"seeds": (3, 3), "pool": 1, "light": None, "fog": None}, max_episode_steps=5)
    try:
        env.reset(seed=0)
        track = get_track(env._episode.built.path)
        assert track.digest not in render_world._albedo_cache
    finally:
        env.close()
        env.worlds.clear()


def test_the_world_built_at_make_gives_the_same_episodes_as_one_built_at_reset(monkeypatch):
    """The same seed, the same observations: building the world at make (and letting its albedo go) changes when
    it is built, not what the env returns (JPEG frames and the model's input)."""
    from tools.envs.client import HeadlessSimClient

    def drive(env: DriveEnv) -> list[np.ndarray]:
        obs, info = env.reset(seed=4)
        frames = [obs]
        for _ in range(10):
            obs, _, _, _, info = env.step(info["expert_action"])
            frames.append(obs)
        env.close()
        return frames

    for observation in ("frame", "model"):
        at_make = drive(DriveEnv(track="lake", observation=observation))
        render_world.clear_caches()
        with monkeypatch.context() as patch:
            patch.setattr(HeadlessSimClient, "prepare", lambda self: None)
            at_reset = drive(DriveEnv(track="lake", observation=observation))
        assert all(np.array_equal(a, b) for a, b in zip(at_make, at_reset, strict=True)), observation
