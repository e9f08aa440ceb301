"""rbc eval's workers are forked from the process that runs it: OpenCV's thread pool, started there by any parallel
OpenCV call (a module computing a constant at import did), must not hang a worker's first parallel call."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHORT = {"min_length_m": 200, "max_length_m": 400, "drive_check": False}  # a 0.2-0.4 km loop

SCRIPT = """
import sys
import cv2
import numpy as np
cv2.setNumThreads(2)  # as a machine with cores to spare has it
cv2.cvtColor(np.zeros((480, 640, 3), np.uint8), cv2.COLOR_RGB2LAB)  # OpenCV's thread pool starts here
from tools.cli import main
sys.exit(main(["eval", "--model", sys.argv[1], "--experiments", "unseen_worlds", "--worlds", "1",
               "--world-config", sys.argv[2], "--workers", "1", "--out", sys.argv[3]]))
"""


def test_rbc_eval_finishes_after_opencv_ran_in_its_process(tmp_path):
    model = REPO / "models" / "pretrained" / "generalist.onnx"
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(model), json.dumps(SHORT), str(tmp_path / "eval")],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "eval" / "results.json").is_file()
