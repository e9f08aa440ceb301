"""The training checkpoint: weights, optimizer, loop position, RNG, and the best epoch's weights so far
(``--export best`` ships those, and a resumed run must still know them)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import torch
from torch import nn

from models.networks import runfiles
from protocol import runrecords
from protocol.errors import UserError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance


class RunDirError(UserError, RuntimeError):
    """The run directory is in a state that does not fit the request (exists, or nothing to resume); the
    message says what to do."""


@dataclass
class State:
    epoch: int = 0
    step: int = 0
    loss_sum: float = 0.0
    loss_count: int = 0
    epoch_seconds: float = 0.0
    history: list[dict[str, float]] = field(default_factory=list)
    best_epoch: int = 0  # 1-based; 0: no epoch validated yet
    best_val: float = float("inf")


def save_checkpoint(path: Path, model: nn.Module, optimizer: torch.optim.Optimizer, state: State,
                    config: DataclassInstance, best: dict[str, torch.Tensor] | None) -> None:
    payload = {"model": model.state_dict(), "optimizer": optimizer.state_dict(), "state": asdict(state),
               "torch_rng": torch.get_rng_state(), "config": asdict(config), "best_model": best}
    runrecords.write_bytes(path, lambda tmp: torch.save(payload, tmp))


def load_checkpoint(path: Path, model: nn.Module,
                    optimizer: torch.optim.Optimizer) -> tuple[State, dict[str, torch.Tensor] | None]:
    try:
        payload = torch.load(path, map_location="cpu", weights_only=False)
        model.load_state_dict(payload["model"])
        optimizer.load_state_dict(payload["optimizer"])
        torch.set_rng_state(payload["torch_rng"])
        return State(**payload["state"]), payload.get("best_model")
    except Exception as exc:  # a truncated, foreign or corrupt file: whatever torch raises for it
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RunDirError(f"{path}: not a readable checkpoint of this run ({first[:120]}); delete it and "
                          f"{runfiles.CONFIG} to train again from the start") from None


def exported_weights(path: Path, export: str = "best") -> dict[str, torch.Tensor]:
    """The weights a run exported (the best epoch's, unless it exported the last)."""
    payload = torch.load(path, map_location="cpu", weights_only=False)
    best = payload.get("best_model")
    return best if export == "best" and best is not None else payload["model"]
