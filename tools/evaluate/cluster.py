"""The Ray backend of ``rbc eval``: every run is a Ray task, journaled on the driver as it arrives.

Ray (not a home-made cluster) schedules the runs over every node; this process keeps the journal, reuse,
progress and summary of :class:`Runner`, so ``--resume``, the tables and plots are the local backend's.
A run is deterministic for its seed, so a run retried after its worker died (or its node was lost) gives
the same record but for its wall time. Retries are the driver's, not Ray's, so each one is logged and
listed in results.json (``meta.retried``) instead of happening silently.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from protocol.errors import UserError
from tools.errors import CommandError
from tools.evaluate.evalrecord import EvalRun
from tools.evaluate.runner import DriverSpec, Runner, Task, pass_on, run_task
from tools.ray_support import BACKENDS, INSTALL_HINT, import_ray, init_ray

if TYPE_CHECKING:
    from ray import ObjectRef

log = logging.getLogger(__name__)
__all__ = ["BACKENDS", "INSTALL_HINT", "RETRIES", "RayRunner", "RunLostError", "import_ray", "make_runner"]

#: attempts after the first before a run counts as lost (a killed worker, a lost node, a crash)
RETRIES = 3


class RunLostError(UserError):
    """A run failed on every attempt; the finished runs are in the journal (``--resume`` continues)."""

    hint = "rbc eval --resume continues from the journal"


class RayRunner(Runner):
    """A :class:`Runner` whose runs are Ray tasks (one CPU each) on a local or an existing cluster.

    ``address`` None starts a private local Ray instance with ``workers`` CPUs on 127.0.0.1 (shut down
    on close); an address (``auto``, ``HOST:6379``) joins a cluster started with ``ray start``, whose CPUs
    set the parallelism. ``task_fn`` is the function each task runs (tests wrap it to kill a worker).
    """

    def __init__(self, spec: DriverSpec, workers: int, journal: Path,
                 on_result: Callable[[EvalRun], None] | None = None,
                 reuse: dict[str, EvalRun] | None = None, *, address: str | None = None,
                 retries: int = RETRIES, task_fn: Callable[[DriverSpec, Task], EvalRun] = run_task) -> None:
        self.address = address
        self.max_retries = retries
        self._task_fn = task_fn
        self._pending: dict[ObjectRef[EvalRun], Future[EvalRun]] = {}  # the run's future (to cancel on Ctrl-C)
        self._closing = threading.Event()
        self._owns_ray = False
        super().__init__(spec, workers, journal, on_result, reuse)

    def _start(self, workers: int) -> ModuleType:  # the engine: Ray itself
        ray = import_ray()
        self._owns_ray = init_ray(ray, workers, self.address)
        self._remote = ray.remote(num_cpus=1, max_retries=0)(self._task_fn)
        self.workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        log.info("Ray backend: %d CPUs (%s)", self.workers, self.address or "local instance")
        return ray

    def _launch(self, task: Task) -> Future[EvalRun]:
        outer: Future[EvalRun] = Future()
        outer.set_running_or_notify_cancel()
        self._attempt(task, outer, 1)
        return outer

    def _attempt(self, task: Task, outer: Future[EvalRun], attempt: int) -> None:
        # Checked and registered under the lock that close() takes to cancel: a range search that submits
        # its next step while Ctrl-C closes the runner gets a cancelled run, never a task on a Ray that is
        # shut down (its future would never resolve, and the search thread would hold the exit forever).
        with self._lock:
            if self._closing.is_set():
                outer.set_exception(RunLostError(f"run {task.experiment} value={task.value} seed={task.seed} "
                                                 "cancelled"))
                return
            ref: ObjectRef[EvalRun] = self._remote.remote(self.spec, task)
            self._pending[ref] = outer
        ref.future().add_done_callback(lambda f: self._settle(task, outer, attempt, ref, f))

    def _record(self, inner: Future[EvalRun], outer: Future[EvalRun]) -> None:
        """Pass the run on: :meth:`_settle` journals a run before its future resolves, so none is missed at close."""
        if pass_on(inner, outer):
            outer.set_result(inner.result())

    def _settle(self, task: Task, outer: Future[EvalRun], attempt: int, ref: ObjectRef[EvalRun],
                done: Future[EvalRun]) -> None:
        with self._lock:
            if self._pending.pop(ref, None) is None:  # already failed by close(cancel=True)
                return
        exc = done.exception()
        if exc is None:
            try:
                self._keep(done.result())  # journaled before anyone waiting on the run sees it
            except OSError as error:  # the journal cannot be written (a full disk): the evaluation stops
                self.failure = self.failure or error
                outer.set_exception(error)
                return
            outer.set_result(done.result())
            return
        what = f"{task.experiment} value={task.value} seed={task.seed}"
        reason = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
        if self._closing.is_set():
            outer.set_exception(RunLostError(f"run {what} cancelled"))
        elif attempt <= self.max_retries:
            log.warning("run %s failed on attempt %d (%s); retrying", what, attempt, reason)
            with self._lock:
                self.retried.append({"experiment": task.experiment, "value": task.value, "seed": task.seed,
                                     "attempt": attempt, "error": reason})
            self._attempt(task, outer, attempt + 1)
        else:
            outer.set_exception(RunLostError(
                f"run {what} failed {attempt} times (last: {reason}); the finished runs are journaled, "
                "rerun with --resume"))

    def close(self, cancel: bool = False) -> None:
        ray = self._pool
        if cancel:
            with self._lock:
                self._closing.set()
                pending, self._pending = self._pending, {}
            for ref, outer in pending.items():
                ray.cancel(ref, force=True)
                outer.set_exception(RunLostError("cancelled"))  # nobody waits forever on a cancelled run
        if self._owns_ray:
            ray.shutdown()


def make_runner(backend: str, spec: DriverSpec, workers: int, journal: Path,
                on_result: Callable[[EvalRun], None] | None = None,
                reuse: dict[str, EvalRun] | None = None, address: str | None = None) -> Runner:
    """The runner of ``--backend``: the local process pool, or Ray tasks."""
    if backend == "ray":
        return RayRunner(spec, workers, journal, on_result, reuse, address=address)
    if address:
        raise CommandError("--address is the Ray cluster's address", "add --backend ray")
    return Runner(spec, workers, journal, on_result, reuse)
