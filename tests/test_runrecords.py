"""Run records: one atomic writer with one file mode for every package, code version, file hashes."""

from __future__ import annotations

import hashlib
import json
import os
import stat

import pytest

from drive_server.observing.stats import LatencyStats, save_stats
from protocol.runrecords import atomic_path, code_version, file_sha256, write_json, write_text


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def _mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_write_json_replaces_atomically_and_leaves_no_temp_file(tmp_path):
    path = tmp_path / "sub" / "stats.json"
    write_json(path, {"a": 1})
    write_json(path, {"a": 2})
    assert json.loads(path.read_text()) == {"a": 2}
    assert [p.name for p in path.parent.iterdir()] == ["stats.json"]


def test_numpy_numbers_are_written_as_numbers_and_paths_as_text(tmp_path):
    """A numpy count summed into a figure was written as the string "22" (rbc data crossval's at_least_95)."""
    import numpy as np

    write_json(tmp_path / "r.json", {"count": sum(np.array([True, False, True])), "eta": np.float32(95.5),
                                     "n": np.int64(3), "where": tmp_path, "flag": np.bool_(True)})
    assert json.loads((tmp_path / "r.json").read_text()) == {"count": 2, "eta": 95.5, "n": 3, "where": str(tmp_path),
                                                             "flag": True}


def test_a_failed_write_keeps_the_old_file(tmp_path):
    path = tmp_path / "keep.txt"
    write_text(path, "old")
    with pytest.raises(RuntimeError), atomic_path(path) as tmp:
        tmp.write_text("half")
        raise RuntimeError("crash mid-write")
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


def test_every_writer_gives_the_same_file_mode(tmp_path, umask_022):
    """The server's stats (JSON and samples) and the training/eval records get 0644, not mkstemp's 0600."""
    write_json(tmp_path / "results.json", {"x": 1})
    write_json(tmp_path / "server_stats.json", {"x": 1}, sort_keys=True)
    save_stats(tmp_path / "samples.npz", [LatencyStats("a")])
    assert {p.name: _mode(p) for p in tmp_path.iterdir()} == {
        "results.json": 0o644, "server_stats.json": 0o644, "samples.npz": 0o644}


def test_file_sha256_and_code_version(tmp_path):
    path = tmp_path / "m.onnx"
    path.write_bytes(b"model bytes")
    assert file_sha256(path) == hashlib.sha256(b"model bytes").hexdigest()
    assert code_version().startswith(("git ", "robust-behavioral-cloning ", "unknown"))
