"""SelfOracle's idea (Stocco et al., ICSE 2020) on the model's own input: a small convolutional autoencoder
learns to reproduce the frames of nominal driving, and its reconstruction error is high on what it never saw
(fog, night, a new road, the car off its line).

Why on the preprocessed input and not the camera frame: drive_server already computes it for steering, so the
monitor adds one small network and no second decode or resize. The exported graph takes exactly the steering
model's input and answers one score, the mean squared error over the pixels.
"""

from __future__ import annotations

import io
import logging
import warnings
from collections.abc import Callable

import numpy as np
import torch
from torch import nn

from drive_server.serving.contract import PreprocessContract
from models.monitoring.training import channels_last, fit_batches, input_resize, network_input, seeded

log = logging.getLogger(__name__)

SCORE_NAME = "autoencoder"


class ConvAutoencoder(nn.Module):
    """Three stride-2 convolutions down to an 8-channel code at 1/8 of the size, and back (about 30k weights)."""

    def __init__(self, channels_last: bool, width: int = 24, code: int = 8,
                 resize: tuple[int, int] | None = None) -> None:
        super().__init__()
        self.channels_last = channels_last
        self.resize = resize  # an input whose sides are not multiples of 8 (PilotNet's 66x200) is resized first
        self.encode = nn.Sequential(
            nn.Conv2d(3, width, 3, 2, 1), nn.ReLU(),
            nn.Conv2d(width, width, 3, 2, 1), nn.ReLU(),
            nn.Conv2d(width, width, 3, 2, 1), nn.ReLU(),
            nn.Conv2d(width, code, 1))
        self.decode = nn.Sequential(
            nn.ConvTranspose2d(code, width, 4, 2, 1), nn.ReLU(),
            nn.ConvTranspose2d(width, width, 4, 2, 1), nn.ReLU(),
            nn.ConvTranspose2d(width, 3, 4, 2, 1))

    def target(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` (the steering model's layout) as the autoencoder sees it: NCHW, resized if it must be."""
        return network_input(x, self.channels_last, self.resize)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The per-frame score: mean squared reconstruction error (shape N)."""
        target = self.target(x)
        return ((self.decode(self.encode(target)) - target) ** 2).mean(dim=(1, 2, 3))


def train_autoencoder(frames: np.ndarray, contract: PreprocessContract, epochs: int = 6, batch_size: int = 128,
                      lr: float = 2e-3, seed: int = 0,
                      progress: Callable[[int, int, float], None] | None = None) -> ConvAutoencoder:
    """Fit on preprocessed frames (N, ...) in the contract's layout; ``progress(epoch, epochs, loss)``."""
    rng = seeded(seed)
    model = ConvAutoencoder(channels_last(contract), resize=input_resize(contract, 8))
    data = torch.from_numpy(np.ascontiguousarray(frames, dtype=np.float32))

    def batch_loss(indices: np.ndarray) -> torch.Tensor:
        return model(data[torch.from_numpy(indices)]).mean()

    fit_batches(model, len(data), batch_loss, rng, epochs, batch_size, lr, progress)
    return model


def scores(model: ConvAutoencoder, frames: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """Per-frame scores of preprocessed frames, in order."""
    out = []
    with torch.no_grad():
        for start in range(0, len(frames), batch_size):
            out.append(model(torch.from_numpy(np.ascontiguousarray(frames[start:start + batch_size]))).numpy())
    return np.concatenate(out) if out else np.zeros(0, np.float32)


def export_score_graph(model: nn.Module, contract: PreprocessContract) -> bytes:
    """The ONNX graph drive_server runs: the steering model's input (batch 1 or more) -> one score per frame."""
    example = torch.zeros(contract.input_shape, dtype=torch.float32)
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter is deprecated but needs no onnxscript
        torch.onnx.export(model.eval(), (example,), buffer,  # type: ignore[arg-type]  # a file object works
                          input_names=["input"], output_names=["score"],
                          dynamic_axes={"input": {0: "batch"}, "score": {0: "batch"}}, opset_version=17,
                          dynamo=False)
    return buffer.getvalue()
