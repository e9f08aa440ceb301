"""The paper's shallow CNN (14,065 parameters) and NVIDIA's PilotNet (252,219), in PyTorch, built from
the layer table of :mod:`models.networks.architectures`.

Both take NCHW float32 input, the layout CPU convolutions are fastest with; ``ContractInput`` wraps
a network so the exported ONNX model takes exactly the layout its preprocessing contract states
(NHWC [N, 64, 64, 3] for the paper's contract) and permutes inside the graph.
"""

from __future__ import annotations

import torch
from torch import nn

from models.networks.architectures import ARCHITECTURES, PILOTNET, SHALLOW, Arch, Architecture


def _init_glorot(module: nn.Module) -> None:
    """Glorot-uniform weights, zero biases (paper Table 6; Keras' defaults)."""
    for m in module.modules():
        if isinstance(m, nn.Conv2d | nn.Linear):
            nn.init.xavier_uniform_(m.weight)
            if m.bias is not None:
                nn.init.zeros_(m.bias)


class TableNet(nn.Module):
    """A network built from a layer table of :mod:`models.networks.architectures` (``features`` then ``head``).

    The submodule order (conv, ReLU, ...; flatten, linear, ReLU[, dropout], ..., linear) is what the
    checkpoints' state-dict keys and :func:`conv_activations` rely on.
    """

    def __init__(self, spec: Architecture, height: int | None = None, width: int | None = None) -> None:
        super().__init__()
        height, width = height or spec.height, width or spec.width
        layers: list[nn.Module] = []
        channels = 3
        for conv in spec.convs:
            layers += [nn.Conv2d(channels, conv.filters, conv.kernel, stride=conv.stride), nn.ReLU()]
            channels = conv.filters
        self.features = nn.Sequential(*layers)
        head: list[nn.Module] = [nn.Flatten()]
        features = _flat_size(self.features, height, width)
        for units in spec.dense:
            head += [nn.Linear(features, units), nn.ReLU()] + ([nn.Dropout(spec.dropout)] if spec.dropout else [])
            features = units
        self.head = nn.Sequential(*head, nn.Linear(features, 1))
        self.spec = spec
        _init_glorot(self)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(x))


def ShallowCNN(height: int = 64, width: int = 64) -> TableNet:  # noqa: N802 (reads like the class it was)
    """Paper Fig. 11: 3 strided convolutions (11x11/5, 5x5/2, 3x3/2) and 3 dropout-regularised dense layers."""
    return TableNet(SHALLOW, height, width)


def PilotNet(height: int = 66, width: int = 200) -> TableNet:  # noqa: N802
    """NVIDIA's PilotNet for 66x200 input: 5 convolutions, 4 dense layers."""
    return TableNet(PILOTNET, height, width)


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


class MirrorAveraged(nn.Module):
    """``(f(x) - f(mirror x)) / 2`` for an NCHW network ``f``: the exported model answers a mirrored road with
    exactly the opposite steering and a symmetric one with exactly 0.

    Training flips half its samples (the paper's augmentation), so the network is symmetric only on
    average; what is left of its asymmetry is noise that both halves carry with opposite signs, and the
    average cancels it. Both halves run as one batch of 2N, so ONNX Runtime makes one pass per layer.
    """

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net = net

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        both = self.net(torch.cat([x, x.flip(-1)]))
        straight, mirrored = both.chunk(2)
        return 0.5 * (straight - mirrored)


def _flat_size(features: nn.Module, height: int, width: int) -> int:
    with torch.no_grad():
        return int(features(torch.zeros(1, 3, height, width)).numel())


def build_model(arch: Arch | str, height: int, width: int) -> nn.Module:
    """A freshly initialised network for the contract's input size."""
    return TableNet(ARCHITECTURES[Arch(arch).value], height, width)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def conv_activations(model: nn.Module, x: torch.Tensor) -> list[torch.Tensor]:
    """Outputs of every convolution layer after its activation (paper Fig. 12), NCHW."""
    out = []
    for layer in model.get_submodule("features").children():  # TableNet's: conv, ReLU, ... (distinct modules)
        x = layer(x)
        if not isinstance(layer, nn.Conv2d):
            out.append(x)
    return out
