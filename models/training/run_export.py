"""The end of a training run: the network as exported (mirror average), scored on the held-out frames,
written to ``model.onnx`` with how it is to be served (gain, smoothing) and recorded in ``config.json``."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from drive_server.serving.preprocess import to_input_tensor
from models.augmentation.fastaug import training_contract
from models.data.behavior import Pipeline
from models.data.trainingdata import PreparedData
from models.networks import runfiles
from models.networks.checkpoint import State
from models.networks.nets import MirrorAveraged, count_parameters
from models.onnxfiles.export import export_onnx
from models.training.metrics import metrics_by_group, steering_metrics
from models.training.recipe import recipe_sections
from models.training.train_config import TrainConfig
from protocol import runrecords
from protocol.rigfile import data_rig

EXPORT_FRAMES = 32


@dataclass
class TrainResult:
    run_dir: Path
    history: list[dict[str, float]]
    onnx: Path | None
    val_loss: float | None
    export_diff: float | None
    interrupted: bool = False
    samples_per_s: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)


def exported_network(model: nn.Module, config: TrainConfig) -> nn.Module:
    """``model`` as the run exports it: mirror-averaged when the configuration asks (training is unchanged by
    it). The serving gain is not part of the network: the model file asks drive_server for it."""
    return MirrorAveraged(model) if config.mirror_average else model


def predict(model: nn.Module, data: PreparedData, pipeline: Pipeline, positions: np.ndarray,
            batch_size: int = 256) -> np.ndarray:
    """Steering predicted for the centre frames at ``positions`` (no augmentation), float32."""
    model.eval()
    contract = training_contract(pipeline.contract)
    out = []
    with torch.no_grad():
        for start in range(0, len(positions), batch_size):
            idx = positions[start:start + batch_size]
            out.append(model(torch.from_numpy(to_input_tensor(data.cache.frames[0, idx], contract))).numpy().ravel())
    return np.concatenate(out) if out else np.zeros(0, np.float32)


def finish(model: nn.Module, data: PreparedData, pipeline: Pipeline, config: TrainConfig, state: State,
            run_dir: Path, rate: float, best: dict | None) -> TrainResult:
    """Export the best epoch (or the last), score it on the held-out frames, record what was exported."""
    last_val = state.history[-1]["val_loss"] if state.history else float("nan")
    exported_epoch = len(state.history)
    if config.export == "best" and best is not None and state.best_epoch:
        model.load_state_dict(best)
        exported_epoch = state.best_epoch
    model = exported_network(model, config)  # what is exported is what is scored below
    predicted = predict(model, data, pipeline, data.val, config.batch_size)
    metrics = steering_metrics(predicted, data.steering[data.val])
    by_recording = [{"log": str(data.dataset.reports[g].log), **m} for g, m in
                    metrics_by_group(predicted, data.steering[data.val], data.recording_groups(data.val)).items()]
    val_loss = state.history[exported_epoch - 1]["val_loss"] if state.history else float("nan")
    info = {"arch": config.arch, "behavior": config.behavior, "approach": config.approach, "val_mse": val_loss,
            "epochs": len(state.history), "train_samples": int(len(data.train)), "seed": config.seed,
            "parameters": count_parameters(model), "code_version": runrecords.code_version(),
            "split": config.split, "export": config.export, "exported_epoch": exported_epoch,
            "val_r": metrics["r"], "val_zero_mse": metrics["zero_mse"], "camera_rig": data_rig(config.data),
            "mirror_average": config.mirror_average, "gain": config.gain,
            "smoothing": config.smoothing, "recipe": recipe_sections(config)}
    frames = data.cache.frames[0, data.val[:EXPORT_FRAMES]]
    path = runfiles.RunPaths(run_dir).model
    diff = export_onnx(model.eval(), pipeline.contract, info, path, frames, config.smoothing, config.gain)
    runfiles.write_result(run_dir, {"export": config.export, "exported_epoch": exported_epoch, "val_mse": val_loss,
                                    "last_epoch_val_mse": last_val, "val_metrics": metrics, "split": config.split,
                                    "rows": data.counts, "onnx_max_diff": diff, "val_by_recording": by_recording})
    return TrainResult(run_dir, state.history, path, val_loss, diff, samples_per_s=rate,
                       info={**info, "metrics": metrics, "summary": data.summary(config.data_options()),
                             "val_by_recording": by_recording})
