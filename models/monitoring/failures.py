"""Runs that failed, as the failure predictor learns from them: the steering model's own input of every frame,
its time, and the run's take-overs, one ``.npz`` per run (``rbc monitor failures`` drives and writes them).

A frame is labelled by what followed it: positive when a misbehaviour (a take-over for leaving the road, a cone
or a spin-out) came within ``horizon_s``, negative when none came within ``quiet_s``, and left out in between
and in the ``settle_s`` after each start and take-over (the car was just put back: the benchmark's own rule).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from protocol.errors import BadValue
from protocol.runrecords import atomic_path

#: Take-over causes that are misbehaviours; stuck and wrong-way are counted apart (the benchmark's rule too).
MISBEHAVIOUR_CAUSES = ("off_road", "cone", "spin_out")
SUFFIX = ".npz"


@dataclass(frozen=True)
class FailureRun:
    """One run: inputs quantised to uint8 (the model's -0.5..0.5 scaled to 0..255), frame times (s), take-overs."""

    name: str
    inputs: np.ndarray  # (N, ...) uint8 in the steering model's input layout, without the batch axis
    t: np.ndarray  # (N,) simulated seconds
    takeovers: tuple[tuple[float, str], ...]
    meta: dict

    def floats(self) -> np.ndarray:
        """The inputs as the steering model reads them (float32, -0.5..0.5)."""
        return self.inputs.astype(np.float32) / 255.0 - 0.5


def quantise(x: np.ndarray) -> np.ndarray:
    """A preprocessed input (-0.5..0.5) as uint8: 1/255 steps, well below what the networks resolve."""
    return np.clip(np.rint((np.asarray(x, np.float32) + 0.5) * 255.0), 0, 255).astype(np.uint8)


def save_run(path: Path, run: FailureRun) -> None:
    with atomic_path(Path(path)) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, inputs=run.inputs, t=run.t.astype(np.float32),
                            takeovers=np.array(json.dumps(list(run.takeovers))),
                            meta=np.array(json.dumps({"name": run.name, **run.meta})))


def load_run(path: Path) -> FailureRun:
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            takeovers = tuple((float(t), str(c)) for t, c in json.loads(str(data["takeovers"])))
            return FailureRun(str(meta.get("name", Path(path).stem)), data["inputs"], data["t"], takeovers, meta)
    except (OSError, KeyError, ValueError) as exc:
        raise BadValue(f"{path}: not a failure run of rbc monitor failures ({exc})") from None


def load_meta(path: Path) -> dict:
    """A run file's metadata alone (an npz reads only the members asked for), to refuse a file before any work."""
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            return dict(json.loads(str(data["meta"])))
    except (OSError, KeyError, ValueError) as exc:
        raise BadValue(f"{path}: not a failure run of rbc monitor failures ({exc})") from None


def run_files(folders: Sequence[Path]) -> list[Path]:
    """Every run file in ``folders``, in name order; BadValue if a folder holds none."""
    out = []
    for folder in folders:
        found = sorted(Path(folder).glob(f"*{SUFFIX}"))
        if not found:
            raise BadValue(f"{folder}: no failure runs (*{SUFFIX}); write some with rbc monitor failures")
        out.extend(found)
    return out


@dataclass(frozen=True)
class LabelRules:
    horizon_s: float = 3.0  # a misbehaviour this soon after a frame makes it positive
    quiet_s: float = 6.0  # none this soon makes it negative; between the two the frame is left out
    settle_s: float = 4.0  # after the start and each take-over: left out


def labels(t: np.ndarray, takeovers: Sequence[tuple[float, str]], rules: LabelRules = LabelRules()) -> np.ndarray:
    """Per frame: 1 positive, 0 negative, -1 left out."""
    t = np.asarray(t, np.float64)
    out = np.zeros(len(t), np.int8)
    out[t < rules.settle_s] = -1
    for when, cause in takeovers:
        after = (t >= when) & (t < when + rules.settle_s)
        out[after] = -1
        if cause in MISBEHAVIOUR_CAUSES:
            ahead = when - t
            out[(ahead > rules.horizon_s) & (ahead <= rules.quiet_s) & (out != 1)] = -1
            out[(ahead > 0) & (ahead <= rules.horizon_s) & (out != -1)] = 1
    return out
