"""The paper's networks as a layer table: the ONE definition that PyTorch training and the torch-free
ONNX builder of random-weight test/benchmark models both build from (no torch, no numpy here)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class Arch(StrEnum):
    """The networks' names (the keys of :data:`ARCHITECTURES`)."""

    SHALLOW = "shallow"
    PILOTNET = "pilotnet"
    SHALLOW_WIDE = "shallow-wide"  # not in the paper: SHALLOW_WIDE below


@dataclass(frozen=True)
class Conv:
    filters: int
    kernel: int
    stride: int = 1


@dataclass(frozen=True)
class Architecture:
    """A CNN of the paper's family: valid-padded ReLU convolutions, flatten, ReLU dense layers (each
    followed by dropout when ``dropout`` > 0, training only), and a final 1-unit linear layer."""

    name: str
    height: int  # the input size the parameter count refers to
    width: int
    convs: tuple[Conv, ...]
    dense: tuple[int, ...]  # hidden sizes; the 1-unit output layer is implied
    params: int  # parameter count at height x width (asserted by both builders)
    dropout: float = 0.0


#: Paper Fig. 11 (verified from the authors' notebook): 14,065 parameters at 64x64.
SHALLOW = Architecture("shallow", 64, 64, (Conv(8, 11, 5), Conv(16, 5, 2), Conv(32, 3, 2)), (64, 16, 8), 14_065,
                       dropout=0.25)
#: NVIDIA's PilotNet (Bojarski et al. 2016): 252,219 parameters at 66x200.
PILOTNET = Architecture("pilotnet", 66, 200,
                        (Conv(24, 5, 2), Conv(36, 5, 2), Conv(48, 5, 2), Conv(64, 3), Conv(64, 3)), (100, 50, 10),
                        252_219)
#: Not in the paper: the shallow CNN's three convolutions at twice the width of input (64x128: the road's
#: edge lines, a pixel or two wide at 320 columns, keep more of their position) with twice the filters, for
#: the real simulator's frames. PilotNet reads real frames better than the shallow CNN but costs twice the
#: 1.0 ms serving budget; this sits between them (about a tenth of PilotNet's multiply-adds).
SHALLOW_WIDE = Architecture("shallow-wide", 64, 128, (Conv(16, 11, 5), Conv(32, 5, 2), Conv(48, 3, 2)), (64, 16, 8),
                            46_065, dropout=0.25)
ARCHITECTURES = {a.name: a for a in (SHALLOW, PILOTNET, SHALLOW_WIDE)}
