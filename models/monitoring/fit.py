"""``rbc monitor fit``'s work: train the autoencoder on nominal frames, calibrate it on other nominal runs, and
write the steering model's file with the monitor attached."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drive_server.model import SteeringModel
from drive_server.monitor import FRAMES_PER_SECOND, MonitorSpec
from models.monitoring.attach import attach_monitor
from models.monitoring.autoencoder import SCORE_NAME as AUTOENCODER
from models.monitoring.autoencoder import export_score_graph, train_autoencoder
from models.monitoring.calibrate import calibrate
from models.monitoring.disagreement import SCORE_NAME as SHIFT
from models.monitoring.disagreement import SHIFT_PIXELS, graph_scores, shift_disagreement_graph
from models.monitoring.frames import load_runs
from protocol.errors import BadValue

log = logging.getLogger(__name__)

#: The scores ``rbc monitor fit`` can attach (``keep``: the model file's own monitor, calibrated afresh).
KEEP = "keep"
SCORES = (AUTOENCODER, SHIFT, KEEP)


@dataclass(frozen=True)
class FitPlan:
    """What to fit: the defaults are defined here once; ``rbc monitor fit``'s flags read them."""

    model: Path
    out: Path
    train: tuple[Path, ...]
    calibration: tuple[Path, ...]
    # or "shift": the model's disagreement with itself on a moved frame (no training); or "keep": the monitor the
    # model file already carries, calibrated afresh (another target rate, other nominal driving)
    score: str = AUTOENCODER
    epochs: int = 6
    stride: int = 2  # every 2nd training frame: neighbours at 15 Hz are near copies
    seed: int = 0
    window: int = FRAMES_PER_SECOND
    warnings_per_hour: float = 10.0
    alarms_per_hour: float = 1.0

    def __post_init__(self) -> None:
        overlap = {p.resolve() for p in self.train} & {p.resolve() for p in self.calibration}
        if overlap:
            raise BadValue(f"calibration data must be other runs than the training data; both have "
                           f"{', '.join(sorted(str(p) for p in overlap))}")
        if self.score not in SCORES:
            raise BadValue(f"unknown score {self.score!r}; choose one of {', '.join(SCORES)}")
        if (self.score == AUTOENCODER and not self.train) or not self.calibration:
            raise BadValue("give calibration data (--calibration), and for the autoencoder training data (--data)")
        if self.epochs < 1 or self.stride < 1:
            raise BadValue(f"epochs and stride must be >= 1, got {self.epochs} and {self.stride}")


@dataclass
class FitResult:
    spec: MonitorSpec
    train_frames: int
    info: dict[str, Any] = field(default_factory=dict)


def fit_monitor(plan: FitPlan, say: Callable[[str], None] = log.info) -> FitResult:
    contract = SteeringModel(plan.model).contract
    record: dict[str, Any] = {"score": plan.score, "seed": plan.seed}
    if plan.score == AUTOENCODER:
        say(f"reading training frames from {len(plan.train)} folder(s) (every {plan.stride}. frame)")
        train = np.concatenate(load_runs(list(plan.train), contract, plan.stride,
                                         progress=lambda d, t: _every_tenth(say, d, t)))
        say(f"training the autoencoder on {len(train):,} frames, {plan.epochs} epochs")
        model = train_autoencoder(train, contract, epochs=plan.epochs, seed=plan.seed,
                                  progress=lambda e, n, loss: say(f"  epoch {e}/{n}: reconstruction error {loss:.5f}"))
        graph = export_score_graph(model, contract)
        record |= {"train_frames": int(len(train)), "train": [p.name for p in plan.train], "epochs": plan.epochs}
    elif plan.score == SHIFT:
        graph = shift_disagreement_graph(plan.model)
        record |= {"shift_pixels": SHIFT_PIXELS}
    else:
        found = SteeringModel(plan.model).monitor()
        if found is None:
            raise BadValue(f"{plan.model.name} carries no monitor to calibrate afresh (--score keep)")
        old, graph_obj = found
        graph = graph_obj.model_bytes
        kept = {k: v for k, v in old.calibration.items() if k in ("train_frames", "train", "epochs", "shift_pixels",
                                                                 "seed")}
        record |= {**kept, "score": old.score, "recalibrated": True}
    say(f"scoring the calibration runs from {len(plan.calibration)} folder(s)")
    runs = load_runs(list(plan.calibration), contract, 1, progress=lambda d, t: _every_tenth(say, d, t))
    cal = calibrate([graph_scores(graph, r) for r in runs], plan.window, plan.warnings_per_hour, plan.alarms_per_hour,
                    source=", ".join(p.name for p in plan.calibration))
    record = {**cal.record, **record}
    spec = MonitorSpec(str(record["score"]), cal.warn, cal.alarm, plan.window, record)
    attach_monitor(plan.model, plan.out, spec, graph)
    return FitResult(spec, int(record.get("train_frames", 0)), record)


def _every_tenth(say: Callable[[str], None], done: int, total: int) -> None:
    """Progress with its total, about ten lines per phase."""
    if done % max(1000, (total // 10000 + 1) * 1000) == 0 or done == total:
        say(f"  {done:,} of {total:,} frames")
