"""Training batches made on a background thread while PyTorch trains on the main one.

On a 2-core machine one core augments (NumPy/OpenCV release the GIL) and the other runs the
network. Every batch is a pure function of (seed, epoch, step): the index stream of an epoch comes
from its own generator and each batch's augmentation draws from a generator seeded with its step,
so a run resumed mid-epoch sees exactly the batches it would have seen.
"""

from __future__ import annotations

import itertools
import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from models.augmentation.fastaug import FastAugmenter, augment_batch
from models.data.balance import index_batches

_INDEX_STREAM, _AUGMENT = 0, 1


@dataclass(frozen=True)
class TrainingSet:
    """What batches are drawn from: positions into the frame cache and their labels."""

    indices: np.ndarray  # cache positions of the training samples
    steering: np.ndarray  # recorded labels, aligned with ``indices``
    has_sides: np.ndarray  # bool, aligned with ``indices``
    deletion_rate: float
    batch_size: int
    groups: np.ndarray | None = None  # recording id per sample, aligned with ``indices``: balance recordings
    middles: np.ndarray | None = None  # the road's middle from the camera (m), aligned with ``indices``: edge pull


def epoch_batches(augmenter: FastAugmenter, data: TrainingSet, seed: int, epoch: int, start: int,
                  stop: int) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """(step, x, y) for steps ``start`` .. ``stop - 1`` of ``epoch``, computed in the calling thread."""
    stream = index_batches(data.steering, data.deletion_rate, data.batch_size,
                           np.random.default_rng([seed, epoch, _INDEX_STREAM]), data.groups)
    for step, local in enumerate(itertools.islice(stream, start, stop), start=start):
        rng = np.random.default_rng([seed, epoch, _AUGMENT, step])
        x, y = augment_batch(augmenter, data.indices[local], data.steering[local], data.has_sides[local], rng,
                             None if data.middles is None else data.middles[local])
        yield step, x, y


class Prefetcher:
    """Runs an iterator on a daemon thread, ``depth`` items ahead; errors surface in the consumer."""

    _DONE = object()

    def __init__(self, source: Iterator, depth: int = 4) -> None:
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(source,), name="rbc-batches", daemon=True)
        self._thread.start()

    def _run(self, source: Iterator) -> None:
        try:
            for item in source:
                if self._stop.is_set():
                    return
                self._put(item)
        except BaseException as exc:  # handed to the consumer
            self._put(exc)
        self._put(self._DONE)

    def _put(self, item: object) -> None:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return
            except queue.Full:
                continue

    def __iter__(self) -> Prefetcher:
        return self

    def __next__(self):
        item = self._queue.get()
        if item is self._DONE:
            raise StopIteration
        if isinstance(item, BaseException):
            raise item
        return item

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
