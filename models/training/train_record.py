"""What ``config.json`` records about a run before it trains: configuration, resolved schedule, data, code."""

from __future__ import annotations

import time
from dataclasses import asdict

import torch

from models.data.behavior import Pipeline
from models.data.split import SplitKind
from models.data.trainingdata import PreparedData
from models.networks.runfiles import ConfigRecord
from models.training.recipe import recipe_sections
from models.training.train_config import TrainConfig
from protocol import runrecords


def config_record(config: TrainConfig, pipeline: Pipeline, data: PreparedData, epochs: int,
                  steps: int, val_steps: int) -> ConfigRecord:
    split = data.split
    return {
        "config": asdict(config),
        "recipe": recipe_sections(config),  # the same settings, resolved, as a recipe file holds them
        "resolved": {
            "epochs": epochs, "steps_per_epoch": steps,
            "validation_steps": val_steps,
            "deletion_rate": pipeline.deletion_rate, "optimizer": "Adam", "loss": "MSE",
            "train_samples": int(len(data.train)), "val_samples": int(len(data.val)),
            "zero_steer_train_samples": int((data.steering[data.train] == 0).sum()),
            "split": {"kind": SplitKind(split.kind).value, "val_fraction": split.val_fraction,
                      "block_frames": split.block_frames, "gap_frames": split.gap_frames},
        },
        "rows": data.counts,
        "augment": asdict(pipeline.augment),
        "contract": asdict(pipeline.contract),
        "logs": [{"path": str(r.log), "rows": r.rows, "samples": r.used, "skipped": len(r.skipped)}
                 for r in data.dataset.reports],
        "unreadable_frames": len(data.cache.errors),
        "code_version": runrecords.code_version(),
        "torch": torch.__version__,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
