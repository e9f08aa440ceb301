"""Training: balance, augment, fit (Adam 1e-3, MSE, batch 256), validate, checkpoint, export to ONNX.

A run directory holds ``config.json`` (everything needed to reproduce the run), ``history.csv``,
``loss.png`` (the loss per epoch, redrawn after each one), ``checkpoint.pt`` and finally ``model.onnx``.
Ctrl-C finishes the current step, saves a checkpoint and returns; ``resume=True`` continues from it with the
stored configuration, batch for batch.

What a run has to say (what data it kept, the network, one line per epoch) goes to ``report``, one line at a
time as it happens: ``rbc train`` prints it; without ``report`` it is logged at INFO. Progress bars are drawn
only on a terminal (tqdm's ``disable=None``), and not at all with ``progress=False``.
"""

from __future__ import annotations

import copy
import logging
import math
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from types import FrameType

import cv2
import numpy as np
import torch
from torch import nn

from models.augmentation.fastaug import FastAugmenter
from models.data.batches import Prefetcher, TrainingSet, epoch_batches
from models.data.behavior import Pipeline
from models.data.trainingdata import PreparedData, prepare_data
from models.networks import runfiles
from models.networks.checkpoint import RunDirError, State, load_checkpoint, save_checkpoint
from models.networks.nets import build_model, count_parameters
from models.training import distributed as ddp
from models.training.run_export import TrainResult, finish, predict
from models.training.run_lines import describe_data, describe_network, draw_loss
from models.training.train_config import TrainConfig
from models.training.train_record import config_record

log = logging.getLogger(__name__)

CHECKPOINT_EVERY_S = 120.0
Report = Callable[[str], None]


__all__ = ["RunDirError", "TrainConfig", "TrainResult", "train"]


def steps_per_epoch(n_train: int, batch_size: int, loops: int) -> int:
    """Paper footnote 10: ceil(n / m) * chi."""
    return math.ceil(n_train / batch_size) * loops


def validation_steps(n_val: int, batch_size: int) -> int:
    """Paper footnote 11: ceil(n / m)."""
    return math.ceil(n_val / batch_size)


def default_threads(arch: str = "shallow") -> int:
    """The shallow CNN trains about as fast as one core makes batches: leave that core to the batch
    thread. PilotNet is ~40x heavier per sample and its batches take ~3 % of a core: use every core."""
    cores = os.cpu_count() or 2
    return cores if arch == "pilotnet" else max(1, cores - 1)


def train(config: TrainConfig, resume: bool = False, report: Report | None = None) -> TrainResult:
    """Train one run: one process, or (under torchrun) rank ``RANK`` of ``WORLD_SIZE`` with DDP. ``report``
    gets the run's lines as they happen (rank 0's only); without it they are logged at INFO."""
    world = ddp.world_from_env()
    ddp.init_world(world)
    try:
        say = (report or _log_info) if world.is_main else log.debug
        return _train(config, resume, world, say)
    finally:
        ddp.close_world(world)


def _log_info(line: str) -> None:
    log.info("%s", line)


def _train(config: TrainConfig, resume: bool, world: ddp.World, say: Report) -> TrainResult:
    run_dir = Path(config.out)
    config = _resolve_config(config, run_dir, resume, world)
    pipeline = config.pipeline()
    epochs = config.epochs or pipeline.epochs
    torch.set_num_threads(config.threads or default_threads(config.arch))
    cv2.setNumThreads(1)
    torch.manual_seed(config.seed)

    model = build_model(config.arch, pipeline.contract.height, pipeline.contract.width)
    optimizer = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    state, best = State(), None
    checkpoint = runfiles.RunPaths(run_dir).checkpoint
    if resume and checkpoint.exists():  # before decoding any frame: a bad checkpoint is reported at once
        state, best = load_checkpoint(checkpoint, model, optimizer)
        say(f"resuming {run_dir} at epoch {state.epoch + 1}, step {state.step}")
    data = _prepare(config, pipeline)
    n_train, n_val = len(data.train), len(data.val)
    steps = steps_per_epoch(n_train, config.batch_size, config.aug_loops)
    if config.max_steps_per_epoch:
        steps = min(steps, config.max_steps_per_epoch)
    if world.is_main and not (resume and checkpoint.exists()):
        record = config_record(config, pipeline, data, epochs, steps, validation_steps(n_val, config.batch_size))
        runfiles.write_config(run_dir, record | {"world_size": world.size})

    for line in describe_data(data, config):
        say(line)
    augmenter = FastAugmenter(data.cache, pipeline.augment)
    tset = TrainingSet(data.train, data.targets[data.train], data.has_sides[data.train], pipeline.deletion_rate,
                       config.batch_size, data.recording_groups(data.train) if config.balance_recordings else None,
                       None if data.middles is None else data.middles[data.train])
    tset = ddp.shard(tset, world)  # this rank's samples and share of the batch (all of both in one process)
    say(describe_network(config, count_parameters(model), epochs, steps))
    trained = 0
    wall = time.perf_counter()
    with _StopFlag() as stop:
        while state.epoch < epochs:
            done = _train_epoch(model, optimizer, augmenter, tset, config, state, steps, stop, checkpoint, best,
                                world)
            trained += done
            if stop.requested and state.step < steps:
                log.warning("interrupted at epoch %d step %d: checkpoint saved; continue with --resume",
                            state.epoch + 1, state.step)
                return TrainResult(run_dir, state.history, None, None, None, interrupted=True,
                                 samples_per_s=trained * config.batch_size / (time.perf_counter() - wall))
            val_loss = evaluate(model, data, pipeline, config.batch_size)
            state.history.append({"epoch": state.epoch + 1, "train_loss": state.loss_sum / max(1, state.loss_count),
                                  "val_loss": val_loss, "seconds": round(state.epoch_seconds, 2)})
            say(f"epoch {state.epoch + 1}/{epochs}: train MSE {state.history[-1]['train_loss']:.5f}  "
                f"val MSE {val_loss:.5f}  {state.epoch_seconds:.0f} s")
            if val_loss < state.best_val:  # strictly lower: ties keep the earlier epoch
                best = copy.deepcopy(model.state_dict())
                state.best_epoch, state.best_val = state.epoch + 1, val_loss
            state = replace(state, epoch=state.epoch + 1, step=0, loss_sum=0.0, loss_count=0, epoch_seconds=0.0)
            if world.is_main:
                runfiles.write_history(run_dir, state.history)
                save_checkpoint(checkpoint, model, optimizer, state, config, best)
                draw_loss(run_dir, state.history)
            if stop.requested and state.epoch < epochs:
                log.warning("interrupted after epoch %d: checkpoint saved; continue with --resume", state.epoch)
                return TrainResult(run_dir, state.history, None, None, None, interrupted=True)
    rate = trained * config.batch_size / max(1e-9, time.perf_counter() - wall)
    if not world.is_main:  # rank 0 exports; the others trained the same weights
        return TrainResult(run_dir, state.history, None, state.best_val, None, samples_per_s=rate,
                           info={"rank": world.rank})
    result = finish(model, data, pipeline, config, state, run_dir, rate, best)
    result.info["loss_plot"] = draw_loss(run_dir, state.history, result.info.get("exported_epoch"))
    return result


def evaluate(model: nn.Module, data: PreparedData, pipeline: Pipeline, batch_size: int) -> float:
    """Validation MSE over every validation sample (centre frames, no augmentation)."""
    pred = predict(model, data, pipeline, data.val, batch_size).astype(np.float64)
    return float(np.mean((pred - data.steering[data.val]) ** 2)) if len(pred) else 0.0


def _train_epoch(model: nn.Module, optimizer: torch.optim.Optimizer, augmenter: FastAugmenter, tset: TrainingSet,
                 config: TrainConfig, state: State, steps: int, stop: _StopFlag, checkpoint: Path,
                 best: dict | None, world: ddp.World = ddp.SINGLE) -> int:
    """Train from ``state.step`` to the end of the epoch (or a Ctrl-C); returns the steps done."""
    from tqdm import tqdm

    if state.step == 0:
        torch.manual_seed(config.seed * 1009 + state.epoch)
    model.train()
    loss_fn = nn.MSELoss()
    source = Prefetcher(epoch_batches(augmenter, tset, ddp.rank_seed(config.seed, world), state.epoch, state.step,
                                      steps))
    net = ddp.wrap(model, world)
    bar = tqdm(total=steps, initial=state.step, desc=f"epoch {state.epoch + 1}", unit="step", leave=False,
               disable=None if config.progress else True, dynamic_ncols=True)  # None: bars on a terminal only
    started = time.perf_counter() - state.epoch_seconds
    last_save = time.perf_counter()
    done = 0
    try:
        for step, x, y in source:
            state.loss_sum += ddp.train_step(net, optimizer, loss_fn, torch.from_numpy(x), torch.from_numpy(y))
            state.loss_count += 1
            state.step = step + 1
            done += 1
            if state.step % 20 == 0:
                bar.set_postfix(mse=f"{state.loss_sum / state.loss_count:.4f}", refresh=False)
            bar.update(1)
            stopping = ddp.agree(stop.requested, world)  # every rank stops at the same step
            if stopping or time.perf_counter() - last_save > CHECKPOINT_EVERY_S:
                state.epoch_seconds = time.perf_counter() - started
                if world.is_main:
                    save_checkpoint(checkpoint, model, optimizer, state, config, best)
                last_save = time.perf_counter()
                if stopping:
                    if not stop.requested:  # another rank's Ctrl-C: this one stops at the same step
                        stop.requested = True
                    break
    finally:
        source.close()
        bar.close()
    state.epoch_seconds = time.perf_counter() - started
    return done


def _prepare(config: TrainConfig, pipeline: Pipeline) -> PreparedData:
    from tqdm import tqdm

    workers = config.decode_workers or max(1, os.cpu_count() or 1)
    with tqdm(desc="decoding frames", unit="sample", disable=None if config.progress else True, leave=False,
              delay=0.5) as bar:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        return prepare_data(config.data, pipeline, config.seed, config.data_options(), workers, progress)


def _resolve_config(config: TrainConfig, run_dir: Path, resume: bool, world: ddp.World = ddp.SINGLE) -> TrainConfig:
    paths = runfiles.RunPaths(run_dir)
    if resume:
        if not paths.config.exists():
            raise RunDirError(f"{run_dir}: nothing to resume (no {runfiles.CONFIG})")
        stored = TrainConfig.from_dict(runfiles.RunRecord.load(run_dir).config, str(paths.config))
        return replace(stored, out=str(run_dir), threads=config.threads, decode_workers=config.decode_workers,
                       progress=config.progress)
    if world.is_main and (paths.checkpoint.exists() or paths.model.exists()):
        raise RunDirError(f"{run_dir} already holds a run: pass --resume to continue it, or choose another --out")
    if not config.data:
        raise RunDirError("no --data given")
    return replace(config, data=[str(Path(d).resolve()) for d in config.data],
                   val_data=[str(Path(d).resolve()) for d in config.val_data])


class _StopFlag:
    """First Ctrl-C asks the loop to stop after the current step; a second one aborts at once."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: Callable[[int, FrameType | None], object] | int | None = None  # signal.signal's

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        log.warning("Ctrl-C: finishing the current step and saving a checkpoint (Ctrl-C again to abort)")

    def __enter__(self) -> _StopFlag:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
