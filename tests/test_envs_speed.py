"""What makes rbc/Drive-v0 fast without changing what it shows: its JPEG decode and vector workers on CPUs of their
own (the figures are ``rbc env-bench``'s, not asserted here)."""

from __future__ import annotations

import builtins
import multiprocessing
import os
from types import SimpleNamespace

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")

from protocol.jpeg import decode_jpeg, encode_jpeg, read_jpeg_file  # noqa: E402
from tests.conftest import UDACITY_SAMPLE  # noqa: E402
from tools.envs import pin_workers, wire_jpeg  # noqa: E402
from tools.envs.wire_jpeg import wire_decoder  # noqa: E402


@pytest.fixture
def fresh_decoder():
    wire_decoder.cache_clear()
    yield
    wire_decoder.cache_clear()


def test_the_env_decodes_real_and_its_own_frames_to_the_pixels_drive_server_decodes(fresh_decoder):
    """Was: every step decoded with OpenCV (0.26 ms a frame, 0.1 ms of it outside libjpeg); the faster decode
    must give the very pixels of protocol.jpeg's, at every scale drive_server uses."""
    pytest.importorskip("simplejpeg", reason="simplejpeg is not installed: the env decodes with protocol.jpeg")
    decode = wire_decoder()
    assert decode is not decode_jpeg
    frames = sorted(UDACITY_SAMPLE.glob("IMG/*.jpg"))[:12]
    assert frames
    for path in frames:
        raw = path.read_bytes()
        ours = encode_jpeg(read_jpeg_file(path))  # re-encoded as the env encodes: another encoder's tables
        for data in (raw, ours):
            for reduce in (1, 2, 4):
                assert np.array_equal(decode(data, reduce), decode_jpeg(data, reduce)), (path.name, reduce)


def test_the_env_keeps_opencvs_decode_without_simplejpeg_or_where_its_pixels_differ(fresh_decoder, monkeypatch):
    real_import = builtins.__import__

    def no_simplejpeg(name, *args, **kwargs):
        if name == "simplejpeg":
            raise ImportError("no simplejpeg here")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_simplejpeg)
    assert wire_decoder() is decode_jpeg
    monkeypatch.setattr(builtins, "__import__", real_import)
    wire_decoder.cache_clear()
    pytest.importorskip("simplejpeg")
    monkeypatch.setattr(wire_jpeg, "_simplejpeg_decode", lambda data, reduce=1: decode_jpeg(data, reduce) // 2)
    assert wire_decoder() is decode_jpeg


def test_an_env_with_jpeg_observations_gives_the_wire_pixels(fresh_decoder):
    from tools.envs import DriveEnv

    env = DriveEnv(track="lake")
    obs, info = env.reset(seed=3)
    for _ in range(5):
        obs, *_, info = env.step(info["expert_action"])
    assert np.array_equal(obs, decode_jpeg(info["jpeg"]))
    env.close()


def _sleep_until_told(ready, done) -> None:
    ready.set()
    done.wait(30)


def test_pin_workers_puts_each_worker_on_a_cpu_of_its_own_round_robin():
    """Was: a vector env's workers woke on whichever core was free, away from their caches (each step 1.42 CPU ms
    against one env's 1.1 on two cores)."""
    if not hasattr(os, "sched_setaffinity"):
        assert pin_workers(SimpleNamespace(processes=[SimpleNamespace(pid=1)])) == {}
        return
    context = multiprocessing.get_context("fork")
    ready, done = context.Event(), context.Event()
    workers = [context.Process(target=_sleep_until_told, args=(ready, done)) for _ in range(3)]
    for worker in workers:
        worker.start()
    try:
        ready.wait(30)
        cpus = sorted(os.sched_getaffinity(0))
        pinned = pin_workers(SimpleNamespace(processes=workers))
        assert pinned == {w.pid: cpus[i % len(cpus)] for i, w in enumerate(workers)}
        for worker in workers:
            assert os.sched_getaffinity(worker.pid) == {pinned[worker.pid]}
        assert pin_workers(SimpleNamespace(processes=workers), cpus=[cpus[-1]]) == {w.pid: cpus[-1] for w in workers}
        assert pin_workers(SimpleNamespace(processes=[SimpleNamespace(pid=None)])) == {}  # not started: left alone
        with pytest.raises(ValueError, match="no CPUs"):
            pin_workers(SimpleNamespace(processes=workers), cpus=[])
    finally:
        done.set()
        for worker in workers:
            worker.join(30)
    gone = pin_workers(SimpleNamespace(processes=workers))  # ended: a warning each, nothing pinned
    assert gone == {}


@pytest.mark.slow
def test_the_documented_make_vec_call_pins_its_workers():
    if not hasattr(os, "sched_setaffinity"):
        pytest.skip("no CPU affinity on this system")
    vec = gym.make_vec("tools.envs:rbc/Drive-v0", num_envs=2, vectorization_mode="async", track="lake")
    try:
        pinned = pin_workers(vec.unwrapped)
        assert len(pinned) == 2
        _, infos = vec.reset(seed=0)
        _, _, _, _, infos = vec.step(infos["expert_action"])
        assert infos["expert_action"].shape == (2, 1)
    finally:
        vec.close()
