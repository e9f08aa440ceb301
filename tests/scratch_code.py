"""A scratch copy of the project's shape: stub modules whose imports mirror the real ones, for the tests that change
one dependency of a cache at a time and watch its key (protocol.codeversion follows the imports)."""

from __future__ import annotations

from pathlib import Path

from protocol import codeversion

STUBS = {
    "protocol/__init__.py": "",
    "protocol/facts.py": "MAX_STEERING_DEG = 25.0\n",
    "drive_server/__init__.py": "",
    "drive_server/serving/__init__.py": "",
    "drive_server/serving/pipeline.py": "from protocol.facts import MAX_STEERING_DEG\n",
    "drive_server/observing/static/dashboard.js": "let page = 1;\n",
    "models/__init__.py": "",
    "models/data/__init__.py": "",
    "models/data/labels.py": "LAG = 0\n",
    "models/training/__init__.py": "",
    "models/training/metrics.py": "def pearson_r(a, b):\n    return 1.0\n",
    "models/training/train.py": "import torch\nfrom models.data import labels\nfrom .metrics import pearson_r\n",
    "models/training/recipe.py": "SECTIONS = ()\n",
    "tools/__init__.py": "",
    "tools/console.py": "BAR = '#'\n",
    "tools/realdata/__init__.py": "",
    "tools/realdata/public_recordings.csv": "name,fold\none,A\n",
    "tools/realdata/recordings.py": "from protocol.facts import MAX_STEERING_DEG\n",
    "tools/realdata/crossval.py": (
        "from typing import TYPE_CHECKING\n\nimport numpy as np\n\nfrom tools.realdata.recordings import X\n\n"
        "if TYPE_CHECKING:\n    from tools.drivelog.loop import LoopRules\n\n\n"
        "def score_recording():\n    \"\"\"Score one.\"\"\"\n    from tools.evaluate.offline import score_models\n"),
    "tools/evaluate/__init__.py": "",
    "tools/evaluate/offline.py": (
        "from models.data import labels\nfrom models.training.metrics import pearson_r\n"
        "from ..sim.driving import rules  # degree_of_autonomy\nimport drive_server.serving.pipeline\n"),
    "tools/evaluate/runner.py": "def run_task(t=0):\n    from tools.sim.driving.session import run_scenario\n",
    "tools/sim/__init__.py": "",
    "tools/sim/driving/__init__.py": "",
    "tools/sim/driving/rules.py": "def degree_of_autonomy(n):\n    return 100.0 - n\n",
    "tools/sim/driving/session.py": "from tools.sim.driving import rules\nfrom tools.sim.track import files\n",
    "tools/sim/track/__init__.py": "",
    "tools/sim/track/files.py": "NAMES = ('lake',)\n",
    "tools/sim/track/builtin/lake.json": "{\"points\": [[0, 0]]}\n",
    "tools/drivelog/__init__.py": "",
    "tools/drivelog/loop.py": "class LoopRules:\n    pass\n",
    "tools/dagger/__init__.py": "",
    "tools/dagger/loop.py": (
        "from tools.console import BAR\n\n\ndef train_round():\n    from models.training.train import train\n"),
    "docs/page.md": "a page\n",
}


def write_tree(root: Path) -> Path:
    """The stub project under ``root``; the per-process cache forgotten, so the next key reads it afresh."""
    for name, text in STUBS.items():
        edit(root, name, text)
    return root


def edit(root: Path, name: str, text: str) -> None:
    """Write one file of the scratch tree and forget the versions worked out before."""
    path = root / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    codeversion.clear_cache()
