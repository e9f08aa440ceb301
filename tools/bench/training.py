"""``rbc train-bench``: where training time goes, and how long the paper's run would take here.

The paper trained the simplistic behavior in ~1.4 h on an RTX 2070: 9,680 training samples, 5 epochs
of ceil(9680/256) * 64 = 2,432 steps of 256, about 3.1 million augmented samples. This measures, on a
dataset of that size (the given frames repeated), the augmentation rate of one core, the network's
training rate, both together as training runs them (one thread makes batches, the other trains), and
projects the wall time of the full run.
"""

from __future__ import annotations

import math
import os
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from models.data.behavior import pipeline_for
from models.training.train_config import TrainConfig

PAPER_TRAIN_SAMPLES = 9680
PAPER_TOTAL_SAMPLES = 12101
TARGET_S = 600.0


@dataclass
class Rate:
    samples_per_s: list[float]

    @property
    def median(self) -> float:
        return statistics.median(self.samples_per_s)

    def __str__(self) -> str:
        lo, hi = min(self.samples_per_s), max(self.samples_per_s)
        return f"{self.median:8.0f} samples/s  (range {lo:.0f}-{hi:.0f} over {len(self.samples_per_s)} runs)"


@dataclass(frozen=True)
class TrainBenchPlan:
    """What one ``rbc train-bench`` measures; the command's flags and their defaults are these fields."""

    data: tuple[Path | str, ...] = ()  # recordings whose frames are repeated to the paper's size (none: synthetic)
    behavior: str = TrainConfig.behavior
    arch: str = TrainConfig.arch
    approach: str = TrainConfig.approach
    steps: int = 150  # batches per measurement
    repeat: int = 3  # measurements per figure (the median is reported)
    threads: int | None = None  # PyTorch threads (None: as rbc train)
    seed: int = 0  # seed of the synthetic frames and the augmentations


def benchmark(plan: TrainBenchPlan) -> int:
    import torch

    from models.augmentation.fastaug import FastAugmenter
    from models.data.batches import Prefetcher, TrainingSet, epoch_batches
    from models.networks.nets import build_model, count_parameters
    from models.training.train import default_threads, steps_per_epoch

    pipeline = pipeline_for(plan.behavior, plan.arch, plan.approach)
    threads = plan.threads or default_threads(plan.arch)
    torch.set_num_threads(threads)
    cv2.setNumThreads(1)
    cache, steering, sides, decode_rate = _paper_sized_cache(plan.data, plan.seed, pipeline)
    n = cache.frames.shape[1]
    train_idx = np.arange(PAPER_TRAIN_SAMPLES)
    tset = TrainingSet(train_idx, steering[train_idx], sides[train_idx], pipeline.deletion_rate, 256)
    augmenter = FastAugmenter(cache, pipeline.augment)
    model = build_model(plan.arch, pipeline.contract.height, pipeline.contract.width)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    loss_fn = torch.nn.MSELoss()
    print(f"dataset: {n} samples x {len(cache.cameras)} camera(s) at {pipeline.contract.width}x"
          f"{pipeline.contract.height} ({cache.nbytes / 1e6:.0f} MB cache); {plan.arch} "
          f"({count_parameters(model)} params), {plan.behavior}/{plan.approach}; torch threads {threads}, "
          f"{torch.get_num_threads()} in use, 1 batch thread")

    cpu: dict[str, list[float]] = {"augment": [], "train": []}

    def augment_only(epoch: int) -> float:
        t, c = time.perf_counter(), time.thread_time()
        for _ in epoch_batches(augmenter, tset, plan.seed, epoch, 0, plan.steps):
            pass
        cpu["augment"].append(plan.steps * 256 / (time.thread_time() - c))
        return plan.steps * 256 / (time.perf_counter() - t)

    batches = [(torch.from_numpy(x), torch.from_numpy(y))
               for _, x, y in epoch_batches(augmenter, tset, plan.seed, 99, 0, 20)]

    def train_step(x: torch.Tensor, y: torch.Tensor) -> None:
        optimizer.zero_grad(set_to_none=True)
        loss = loss_fn(model(x), y)
        loss.backward()
        optimizer.step()

    def train_only(_: int) -> float:
        t, c = time.perf_counter(), time.thread_time()
        for k in range(plan.steps):
            train_step(*batches[k % len(batches)])
        if threads == 1:  # one intra-op thread runs in the calling thread: its CPU time is the step's
            cpu["train"].append(plan.steps * 256 / (time.thread_time() - c))
        return plan.steps * 256 / (time.perf_counter() - t)

    def end_to_end(epoch: int) -> float:
        source = Prefetcher(epoch_batches(augmenter, tset, plan.seed, epoch, 0, plan.steps))
        t = time.perf_counter()
        try:
            for _, x, y in source:
                train_step(torch.from_numpy(x), torch.from_numpy(y))
        finally:
            source.close()
        return plan.steps * 256 / (time.perf_counter() - t)

    def validate(_: int) -> float:
        model.eval()
        x = batches[0][0]
        t = time.perf_counter()
        with torch.no_grad():
            for _ in range(10):
                model(x)
        model.train()
        return 10 * 256 / (time.perf_counter() - t)

    train_only(0)  # warm-up (allocator, kernels)
    cpu["train"].clear()
    load_before = os.getloadavg()[0]
    timings: dict[str, float] = {}
    aug, trn, e2e, val = Rate([]), Rate([]), Rate([]), Rate([])
    for r in range(plan.repeat):  # interleaved, so a busy moment on a shared machine hits all figures alike
        augmenter.timings = timings
        aug.samples_per_s.append(augment_only(r))
        augmenter.timings = None
        trn.samples_per_s.append(train_only(r))
        e2e.samples_per_s.append(end_to_end(r))
        val.samples_per_s.append(validate(r))

    load_after = os.getloadavg()[0]
    print(f"machine load average {load_before:.1f} -> {load_after:.1f} on {os.cpu_count()} cores "
          f"(others' work slows wall-clock figures; CPU-time figures are immune)")
    print(f"augmentation (1 thread):      {aug}")
    total = sum(timings.values())
    for stage, seconds in sorted(timings.items(), key=lambda kv: -kv[1]):
        print(f"    {stage:16s} {1e3 * seconds / (plan.steps * plan.repeat):6.2f} ms/batch  "
              f"({100 * seconds / total:4.1f} %)")
    print(f"training fwd+bwd+Adam:        {trn}")
    print(f"end to end (train + batches): {e2e}")
    cpu_aug = statistics.median(cpu["augment"])
    cpu_trn = statistics.median(cpu["train"]) if cpu["train"] else trn.median
    print(f"per CPU-second of its own thread: augmentation {cpu_aug:.0f} samples, training {cpu_trn:.0f} samples")
    print(f"validation forward:           {val}")
    if decode_rate:
        print(f"decoding JPEG -> cache:       {decode_rate:8.0f} frames/s (2 threads)")

    spec_epochs = pipeline.epochs
    steps = steps_per_epoch(PAPER_TRAIN_SAMPLES, 256, 64)
    samples = spec_epochs * steps * 256
    train_s = samples / e2e.median
    val_s = spec_epochs * (PAPER_TOTAL_SAMPLES - PAPER_TRAIN_SAMPLES) / val.median
    decode_s = PAPER_TOTAL_SAMPLES * len(cache.cameras) / decode_rate if decode_rate else 0.0
    projected = train_s + val_s + decode_s
    free_s = samples / min(cpu_aug, cpu_trn) + val_s + decode_s
    print(f"paper-sized run: {PAPER_TRAIN_SAMPLES} samples, {spec_epochs} epochs x {steps} steps x 256 = "
          f"{samples / 1e6:.2f} M augmented samples")
    print(f"projected wall time: {projected / 60:.1f} min (training {train_s / 60:.1f} min, validation "
          f"{val_s:.0f} s, decoding {decode_s:.0f} s); paper: ~84 min on an RTX 2070")
    print(f"on two otherwise idle cores (from CPU time, the slower thread bounds): {free_s / 60:.1f} min")
    verdict = "met" if projected <= TARGET_S else "NOT met"
    bound = "the network" if cpu_trn < cpu_aug else "making batches"
    print(f"target <= {TARGET_S / 60:.0f} min: {verdict} (needs >= {samples / TARGET_S:.0f} samples/s end to end; "
          f"the slower side alone is {bound})")
    return 0


def _paper_sized_cache(data_dirs: tuple[Path | str, ...], seed: int, pipeline):
    """Frames of the given recordings (or synthetic ones) repeated to the paper's 12,101 samples."""
    from models.data.framecache import FrameCache
    from models.data.trainingdata import prepare_data

    cams = 3 if pipeline.augment.uses_side_cameras else 1
    c = pipeline.contract
    decode_rate = 0.0
    if data_dirs:
        t = time.perf_counter()
        data = prepare_data(data_dirs, pipeline, seed)
        decode_rate = data.cache.frames.shape[0] * len(data.dataset.samples) / (time.perf_counter() - t)
        base = data.cache.frames[:, data.usable]
        steering = data.steering[data.usable]
        sides = data.has_sides[data.usable]
    else:
        rng = np.random.default_rng(seed)
        small = rng.integers(0, 256, (cams, 64, c.height // 4 + 1, c.width // 4 + 1, 3), dtype=np.uint8)
        base = np.stack([[cv2.resize(f, (c.width, c.height), interpolation=cv2.INTER_CUBIC) for f in cam]
                         for cam in small])
        steering = np.where(rng.random(64) < 0.7, 0.0, rng.uniform(-0.5, 0.5, 64)).astype(np.float32)
        sides = np.full(64, cams == 3)
    reps = math.ceil(PAPER_TOTAL_SAMPLES / base.shape[1])
    frames = np.ascontiguousarray(np.tile(base, (1, reps, 1, 1, 1))[:, :PAPER_TOTAL_SAMPLES])
    cache = FrameCache(frames, ("center", "left", "right")[:frames.shape[0]], c,
                       np.ones(PAPER_TOTAL_SAMPLES, bool), [])
    return (cache, np.tile(steering, reps)[:PAPER_TOTAL_SAMPLES], np.tile(sides, reps)[:PAPER_TOTAL_SAMPLES],
            decode_rate)
