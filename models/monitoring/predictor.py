"""A failure predictor: a small CNN on the steering model's own input that answers the probability that the car
misbehaves within the next few seconds, learnt from runs of that model that failed and runs that did not.

Why: SelfOracle's autoencoder and the model's disagreement with itself score how unusual a frame looks; the
benchmark found the frames before a failure look ordinary to both (the car drifts towards the edge of an ordinary
road). What precedes a failure is where the car is on the road and where it heads, which a network can read from
the same picture the steering model reads. It is the supervised route of the misbehaviour-prediction literature
(Stocco et al.'s later work, DeepGuard's use of failure labels), trained only on training worlds, and calibrated
like every other score: on nominal driving, for a target false-alarm rate.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import torch
from torch import nn

from drive_server.serving.contract import PreprocessContract
from models.monitoring.training import channels_last, fit_batches, input_resize, network_input, seeded

log = logging.getLogger(__name__)

SCORE_NAME = "predictor"


class FailurePredictor(nn.Module):
    """Four stride-2 convolutions, a global average and a linear head; the answer is a probability (shape N)."""

    def __init__(self, channels_last: bool, width: int = 24, resize: tuple[int, int] | None = None) -> None:
        super().__init__()
        self.channels_last, self.resize = channels_last, resize
        self.features = nn.Sequential(
            nn.Conv2d(3, width, 3, 2, 1), nn.ReLU(),
            nn.Conv2d(width, width, 3, 2, 1), nn.ReLU(),
            nn.Conv2d(width, 2 * width, 3, 2, 1), nn.ReLU(),
            nn.Conv2d(2 * width, 2 * width, 3, 2, 1), nn.ReLU())
        self.head = nn.Linear(2 * width, 1)

    def logits(self, x: torch.Tensor) -> torch.Tensor:
        x = network_input(x, self.channels_last, self.resize)
        return self.head(self.features(x).mean(dim=(2, 3))).reshape(-1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(self.logits(x))


def train_predictor(frames: np.ndarray, targets: np.ndarray, contract: PreprocessContract, epochs: int = 6,
                    batch_size: int = 128, lr: float = 2e-3, seed: int = 0,
                    progress: Callable[[int, int, float], None] | None = None) -> FailurePredictor:
    """Fit on uint8-quantised inputs (N, ...) labelled 1 (a failure follows) or 0; each class weighs half of the
    loss whatever its count (failures are the rarer frames). ``progress(epoch, epochs, loss)``."""
    if frames.dtype != np.uint8 or len(frames) != len(targets):
        raise ValueError("frames must be uint8 inputs, one per target")
    positives = int(targets.sum())
    if positives == 0 or positives == len(targets):
        raise ValueError(f"the failure runs give {positives} frames before a failure of {len(targets)}: both kinds "
                         "are needed")
    rng = seeded(seed)
    model = FailurePredictor(channels_last(contract), resize=input_resize(contract, 16))
    pos_weight = torch.tensor((len(targets) - positives) / positives, dtype=torch.float32)
    loss_fn = nn.BCEWithLogitsLoss(pos_weight=pos_weight)
    y = torch.from_numpy(targets.astype(np.float32))

    def batch_loss(indices: np.ndarray) -> torch.Tensor:
        idx = np.sort(indices)
        x = torch.from_numpy(frames[idx].astype(np.float32) / 255.0 - 0.5)
        if rng.random() < 0.5:  # a mirrored road fails as often: flip the picture (the label stays)
            x = torch.flip(x, dims=(2 if model.channels_last else 3,))
        return loss_fn(model.logits(x), y[idx])

    fit_batches(model, len(frames), batch_loss, rng, epochs, batch_size, lr, progress)
    return model
