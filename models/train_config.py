"""What determines a training run, torch-free so the command line can read its defaults without torch."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from models.behavior import AUGMENTATION_LOOPS, BATCH_SIZE, LEARNING_RATE


@dataclass
class TrainConfig:
    """Everything that determines a run. ``None`` means the paper's value for the behavior."""

    data: list[str]
    out: str
    behavior: str = "simplistic"
    arch: str = "shallow"
    approach: str = "ours"
    epochs: int | None = None
    aug_loops: int = AUGMENTATION_LOOPS
    batch_size: int = BATCH_SIZE
    learning_rate: float = LEARNING_RATE
    seed: int = 0
    max_steps_per_epoch: int | None = None
    val_fraction: float = 0.2
    # execution only (do not change results beyond float noise)
    threads: int | None = None
    decode_workers: int | None = None
    progress: bool = True

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        known = set(cls.__dataclass_fields__)
        return cls(**{k: v for k, v in data.items() if k in known})
