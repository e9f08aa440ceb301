"""Open-loop scores of models on a recorded driving log: how well each predicts the recorded steering.

This is the sim-to-real figure of the generalisation study: the bundled models learnt in the headless
simulator, so their predictions on real Unity frames show how far that transfers. Every frame goes
through drive_server's own pipeline (the same JPEG decode and preprocessing contract), so a score is
what the server would have steered; the baseline to beat is always predicting 0.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from drive_server.serving.model import SteeringModel
from drive_server.serving.pipeline import DriveConfig, DrivePipeline
from drive_server.serving.smoothing import OFF
from models.data.labels import centred_average
from models.training.metrics import steering_metrics
from protocol.datalog import Sample, read_log
from protocol.errors import BadValue
from protocol.jpeg import read_jpeg_file

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class OfflineScore:
    """One model's predictions against one log's recorded steering (normalised -1..1)."""

    model: str
    frames: int
    mse: float
    pearson_r: float
    zero_mse: float
    # against the recorded steering averaged over ``smooth_frames`` (what a keyboard driver meant); 0: not asked
    smooth_frames: int = 0
    mse_smoothed: float | None = None
    pearson_r_smoothed: float | None = None
    # r of the recorded steering with that average: what predicting the average exactly would score
    intent_r: float | None = None
    smooth: float = OFF  # the model's steering was smoothed over the log's frames as drive_server does (1: not)

    @property
    def beats_zero(self) -> bool:
        return self.mse < self.zero_mse

    def as_dict(self) -> dict:
        return {**asdict(self), "beats_zero": self.beats_zero}


def camera_frames(samples: Sequence[Sample], camera: str) -> list[tuple[Path, float]]:
    """(frame file, recorded steering) of ``camera`` for every row that has that camera's frame."""
    frames = [(getattr(s, camera), s.steering) for s in samples]
    return [(path, steering) for path, steering in frames if path is not None]


def score_model(model_path: Path, frames: Sequence[tuple[Path, float]],
                on_frame: Callable[[], None] | None = None, smooth_frames: int = 0,
                smooth: float | None = None) -> OfflineScore:
    # the network's own answer: the serving gain is for the closed loop (drive_server.serving.settings), not scored here
    pipeline = DrivePipeline(SteeringModel(model_path), DriveConfig(smoothing=smooth, gain=1.0))
    smoother = pipeline.smoother()
    pred = np.empty(len(frames))
    for i, (path, _) in enumerate(frames):
        pred[i] = pipeline.steer(read_jpeg_file(path, reduce=pipeline.reduce), smoother)
        if on_frame:
            on_frame()
    truth = np.array([steering for _, steering in frames])
    m = steering_metrics(pred, truth)
    score = OfflineScore(model=str(model_path), frames=int(m["n"]), mse=m["mse"], pearson_r=m["r"],
                         zero_mse=m["zero_mse"], smooth=pipeline.smoothing)
    if smooth_frames > 1:
        intent = centred_average(truth, smooth_frames)
        ms = steering_metrics(pred, intent)
        score = replace(score, smooth_frames=smooth_frames, mse_smoothed=ms["mse"], pearson_r_smoothed=ms["r"],
                        intent_r=steering_metrics(intent, truth)["r"])
    return score


def score_models(models: Sequence[Path], data: Path, camera: str = "center",
                 on_frame: Callable[[], None] | None = None, smooth_frames: int = 0,
                 smooth: float | None = None) -> list[OfflineScore]:
    """Each model's :class:`OfflineScore` on the log in ``data`` (rows without the camera's frame skipped).

    ``smooth_frames`` > 1 also scores against the recorded steering's centred average over that many
    frames (:func:`centred_average`), in log order. Each model's steering is smoothed over the frames in log
    order as drive_server does for one client: by ``smooth``, or (None) as the model's metadata asks.
    """
    samples, report = read_log(data)
    if report.skipped:
        log.warning("%s", report.summary())
    frames = camera_frames(samples, camera)
    if not frames:
        raise BadValue(f"{data}: no row has a {camera} frame")
    return [score_model(Path(m), frames, on_frame, smooth_frames, smooth) for m in models]
