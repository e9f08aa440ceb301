"""The paper's shallow CNN (14,065 parameters) and NVIDIA's PilotNet (252,219), in PyTorch.

Both take NCHW float32 input, the layout CPU convolutions are fastest with; ``ContractInput`` wraps
a network so the exported ONNX model takes exactly the layout its preprocessing contract states
(NHWC [N, 64, 64, 3] for the paper's contract) and permutes inside the graph.
"""

from __future__ import annotations

import torch
from torch import nn

from models.behavior import Arch


def _init_glorot(module: nn.Module) -> None:
    """Glorot-uniform weights, zero biases (paper Table 6; Keras' defaults)."""
    for m in module.modules():
        if isinstance(m, nn.Conv2d | nn.Linear):
            nn.init.xavier_uniform_(m.weight)
            if m.bias is not None:
                nn.init.zeros_(m.bias)


class ShallowCNN(nn.Module):
    """Paper Fig. 11: 3 strided convolutions (11x11/5, 5x5/2, 3x3/2) and 3 dropout-regularised dense layers."""

    def __init__(self, height: int = 64, width: int = 64, dropout: float = 0.25) -> None:
        super().__init__()
        self.features = nn.Sequential(
            nn.Conv2d(3, 8, 11, stride=5), nn.ReLU(),
            nn.Conv2d(8, 16, 5, stride=2), nn.ReLU(),
            nn.Conv2d(16, 32, 3, stride=2), nn.ReLU(),
        )
        flat = _flat_size(self.features, height, width)
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.Linear(flat, 64), nn.ReLU(), nn.Dropout(dropout),
            nn.Linear(64, 16), nn.ReLU(), nn.Dropout(dropout),
            nn.Linear(16, 8), nn.ReLU(), nn.Dropout(dropout),
            nn.Linear(8, 1),
        )
        _init_glorot(self)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x))


class PilotNet(nn.Module):
    """NVIDIA's PilotNet (Bojarski et al. 2016) for 66x200 input: 5 convolutions, 4 dense layers."""

    def __init__(self, height: int = 66, width: int = 200) -> None:
        super().__init__()
        self.features = nn.Sequential(
            nn.Conv2d(3, 24, 5, stride=2), nn.ReLU(),
            nn.Conv2d(24, 36, 5, stride=2), nn.ReLU(),
            nn.Conv2d(36, 48, 5, stride=2), nn.ReLU(),
            nn.Conv2d(48, 64, 3), nn.ReLU(),
            nn.Conv2d(64, 64, 3), nn.ReLU(),
        )
        flat = _flat_size(self.features, height, width)
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.Linear(flat, 100), nn.ReLU(),
            nn.Linear(100, 50), nn.ReLU(),
            nn.Linear(50, 10), nn.ReLU(),
            nn.Linear(10, 1),
        )
        _init_glorot(self)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x))


class ContractInput(nn.Module):
    """Adapts an NCHW network to the contract's input layout (for export and serving)."""

    def __init__(self, net: nn.Module, layout: str) -> None:
        super().__init__()
        self.net = net
        self.layout = layout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.layout == "nhwc":
            x = x.permute(0, 3, 1, 2)
        return self.net(x)


def _flat_size(features: nn.Module, height: int, width: int) -> int:
    with torch.no_grad():
        return int(features(torch.zeros(1, 3, height, width)).numel())


def build_model(arch: Arch | str, height: int, width: int) -> nn.Module:
    """A freshly initialised network for the contract's input size."""
    arch = Arch(arch)
    if arch is Arch.SHALLOW:
        return ShallowCNN(height, width)
    return PilotNet(height, width)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def conv_activations(model: nn.Module, x: torch.Tensor) -> list[torch.Tensor]:
    """Outputs of every convolution layer after its activation (paper Fig. 12), NCHW."""
    out = []
    features = model.features  # type: ignore[attr-defined]
    for layer in features:
        x = layer(x)
        if not isinstance(layer, nn.Conv2d):
            out.append(x)
    return out
