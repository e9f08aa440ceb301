"""The package as a user gets it from an index: metadata complete, the sdist able to run its own tests."""

from __future__ import annotations

import subprocess
import sys
import tarfile
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))


def test_metadata_is_complete():
    data = _pyproject()
    project = data["project"]
    assert project["license"] == "MIT" and project["keywords"] and project["classifiers"] and project["urls"]
    requires = data["build-system"]["requires"]
    assert any(r.replace(" ", "").startswith("setuptools>=") and int(r.split(">=")[1].split(".")[0]) >= 77
               for r in requires), "the SPDX license string needs setuptools >= 77"


@pytest.mark.slow
def test_the_sdist_holds_what_its_tests_and_readme_need(tmp_path):
    pytest.importorskip("build")
    try:
        import setuptools

        isolation = [] if int(setuptools.__version__.split(".")[0]) >= 77 else None
    except ImportError:
        isolation = None
    args = [sys.executable, "-m", "build", "--sdist", "--outdir", str(tmp_path)]
    args += ["--no-isolation"] if isolation is not None else []
    subprocess.run(args, cwd=REPO, check=True, capture_output=True, timeout=300)
    (sdist,) = tmp_path.glob("*.tar.gz")
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    needed = {"tests/conftest.py", "tests/helpers_server.py", "tests/data/udacity-sample/driving_log.csv",
              "tests/js/drive_client.js", "docs/img/demo_map.png", "docs/img/sim_sheet.jpg", "LICENSE", "README.md",
              "models/pretrained/simplistic.onnx", "tools/sim/track/builtin/lake.json", "pyproject.toml",
              ".ci/run", "requirements-imitation.txt"}
    assert needed <= names, sorted(needed - names)
    readme_images = {line.split("](", 1)[1].split(")", 1)[0] for line in (REPO / "README.md").read_text().splitlines()
                     if line.startswith("![")}
    assert readme_images <= names, sorted(readme_images - names)
    assert not any("__pycache__" in n or n.endswith(".pyc") for n in names)
