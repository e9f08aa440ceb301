"""What the monitor's trained networks share: the autoencoder and the failure predictor differ only in the
network and in how a batch becomes a loss, so the seeding, the input's layout and resize, the optimiser, its
schedule and the epochs over shuffled batches are written here once (the same seed gives the same weights)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torch import nn

from drive_server.serving.contract import PreprocessContract

#: The side an input whose sides a network's total stride does not divide is resized to first (the shallow
#: CNN's own 64x64).
RESIZED = 64


def seeded(seed: int) -> np.random.Generator:
    """Seed torch (the network's initial weights) and return the stream that shuffles the batches."""
    torch.manual_seed(seed)
    return np.random.default_rng(seed)


def input_resize(contract: PreprocessContract, stride: int) -> tuple[int, int] | None:
    """None where ``stride`` divides both sides of the contract's input, else the square it is resized to
    (PilotNet's 66x200 goes through no stack of stride-2 layers evenly)."""
    return None if contract.height % stride == 0 and contract.width % stride == 0 else (RESIZED, RESIZED)


def channels_last(contract: PreprocessContract) -> bool:
    """Whether the steering model's input (and so the monitor's) is NHWC."""
    return contract.layout.lower() == "nhwc"


def network_input(x: torch.Tensor, nhwc: bool, resize: tuple[int, int] | None) -> torch.Tensor:
    """The steering model's input as the monitor's networks take it: NCHW, resized where ``resize`` says."""
    if nhwc:
        x = x.permute(0, 3, 1, 2)
    if resize is not None:
        x = nn.functional.interpolate(x, size=resize, mode="bilinear", align_corners=False)
    return x


def fit_batches(model: nn.Module, count: int, batch_loss: Callable[[np.ndarray], torch.Tensor],
                rng: np.random.Generator, epochs: int, batch_size: int, lr: float,
                progress: Callable[[int, int, float], None] | None = None) -> nn.Module:
    """Adam with a cosine schedule over ``epochs`` passes of shuffled full batches of ``count`` samples;
    ``batch_loss(indices)`` is a batch's mean loss; ``progress(epoch, epochs, mean loss)``. The model, in eval
    mode."""
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs * max(1, count // batch_size))
    for epoch in range(epochs):
        model.train()
        order = rng.permutation(count)
        total, seen = 0.0, 0
        for start in range(0, count - batch_size + 1, batch_size):
            indices = order[start:start + batch_size]
            loss = batch_loss(indices)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total, seen = total + loss.item() * len(indices), seen + len(indices)
        if progress is not None:
            progress(epoch + 1, epochs, total / max(1, seen))
    return model.eval()
