"""The code version of a computation is derived from what it imports: every module it reaches, the data beside
them and the libraries it loads count; nothing else does."""

from __future__ import annotations

from pathlib import Path

import pytest

from protocol import codeversion
from protocol.codeversion import code_digest, code_version, data_digest, module_closure
from tests.scratch_code import STUBS, edit, write_tree

ENTRY = "tools.realdata.crossval"


def test_the_closure_follows_imports_in_functions_relative_ones_and_packages_but_not_type_checking(
        tmp_path: Path) -> None:
    root = write_tree(tmp_path)
    assert module_closure([ENTRY], root) == sorted([
        "drive_server", "drive_server.serving", "drive_server.serving.pipeline", "models", "models.data",
        "models.data.labels", "models.training", "models.training.metrics", "protocol", "protocol.facts", "tools",
        "tools.evaluate", "tools.evaluate.offline", "tools.realdata", "tools.realdata.crossval",
        "tools.realdata.recordings", "tools.sim", "tools.sim.driving", "tools.sim.driving.rules"])
    assert module_closure(["tools.evaluate.runner"], root)[:2] == ["tools", "tools.evaluate"]  # its own package
    assert set(code_version(ENTRY, root=root).libraries) == {"numpy"}
    with pytest.raises(ValueError, match="no module tools.nowhere"):
        code_version("tools.nowhere", root=root)


@pytest.mark.parametrize("name", ["tools/realdata/crossval.py", "tools/evaluate/offline.py", "models/data/labels.py",
                                  "models/training/metrics.py", "tools/sim/driving/rules.py", "protocol/facts.py",
                                  "models/training/__init__.py", "tools/realdata/public_recordings.csv"])
def test_a_change_to_any_module_reached_or_the_data_beside_it_changes_the_version(tmp_path: Path, name: str) -> None:
    root = write_tree(tmp_path)
    before = code_digest(ENTRY, root=root)
    edit(root, name, STUBS[name] + "\nCHANGED = 1\n")
    assert code_digest(ENTRY, root=root) != before


@pytest.mark.parametrize("name, text", [
    ("models/training/train.py", "import torch\n"),  # not reached from the scorer
    ("tools/drivelog/loop.py", "class LoopRules:\n    x = 1\n"),  # only under TYPE_CHECKING
    ("docs/page.md", "another page\n"),
    ("drive_server/observing/static/dashboard.js", "let page = 2;\n"),  # a web page's assets are no data
    ("tools/evaluate/offline.py", STUBS["tools/evaluate/offline.py"] + "\n# a comment\n\n"),
    ("tools/realdata/crossval.py", STUBS["tools/realdata/crossval.py"].replace("Score one.", "Score one recording.")),
])
def test_a_change_outside_the_code_that_runs_or_to_its_comments_keeps_the_version(
        tmp_path: Path, name: str, text: str) -> None:
    root = write_tree(tmp_path)
    before = code_digest(ENTRY, root=root)
    edit(root, name, text)
    assert code_digest(ENTRY, root=root) == before


def test_another_version_of_a_library_it_imports_changes_the_version(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = write_tree(tmp_path)
    before = code_digest(ENTRY, root=root)
    real = codeversion.metadata.version
    monkeypatch.setattr(codeversion.metadata, "version", lambda d: "0.0.1" if d == "numpy" else real(d))
    codeversion.clear_cache()
    assert code_digest(ENTRY, root=root) != before


def test_the_version_is_worked_out_once_per_process(tmp_path: Path) -> None:
    root = write_tree(tmp_path)
    before = code_version(ENTRY, root=root)
    (root / "models/training/metrics.py").write_text("CHANGED = 1\n", encoding="utf-8")
    assert code_version(ENTRY, root=root) is before  # not read again
    codeversion.clear_cache()
    assert code_version(ENTRY, root=root).digest != before.digest
    assert code_digest(ENTRY) == code_digest(ENTRY)  # the checkout's own, stable


def test_the_data_digest_reads_a_log_by_content_and_frames_by_name_and_size(tmp_path: Path) -> None:
    rec = tmp_path / "rec"
    (rec / "IMG").mkdir(parents=True)
    (rec / "driving_log.csv").write_text("a,b,c,0.1,0,0,1\n", encoding="utf-8")
    (rec / "IMG" / "a.jpg").write_bytes(b"\xff\xd8" + b"1" * 10)
    digests = [data_digest([rec])]
    (rec / "driving_log.csv").write_text("a,b,c,0.2,0,0,1\n", encoding="utf-8")
    digests.append(data_digest([rec]))
    (rec / "IMG" / "a.jpg").write_bytes(b"\xff\xd8" + b"1" * 11)
    digests.append(data_digest([rec]))
    (rec / "IMG" / "b.jpg").write_bytes(b"\xff\xd8")
    digests.append(data_digest([rec]))
    assert len(set(digests)) == 4
    assert data_digest([rec]) == data_digest([rec])
