"""Where the worlds of ``rbc collect --worlds`` are driven: this process, a process pool, or Ray tasks.

One job is one world: generate it, write its track file, drive the autopilot through it into the
world's own folder (:func:`collect_world`). Every backend yields (job, outcome) as worlds finish; the
caller journals and assembles them in seed order, so the data set never depends on the backend.
A Ray task may run on another machine: it collects into a temporary folder there and returns the
files, which :func:`unpack` writes where the local backends would have.
"""

from __future__ import annotations

import datetime as dt
import itertools
import logging
import os
import tempfile
import time
from collections.abc import Generator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

from protocol.errors import BadValue
from protocol.runrecords import file_sha256, write_bytes
from tools.ray_support import BACKENDS
from tools.sim.collect.dataset import CollectConfig, collect
from tools.sim.worldgen import WorldGenConfig, write_world

log = logging.getLogger(__name__)

#: Simulated time reserved for one world's drives: world i's frames are named from day i of the epoch.
WORLD_TIME_SLOT = dt.timedelta(days=1)
_WORLD_FILE, _WORLD_FOLDER = "world.json", "world"  # names inside a Ray task's temporary folder


@dataclass(frozen=True)
class WorldJob:
    index: int  # position of the world in the collection (its time slot)
    seed: int
    collect: CollectConfig  # the per-world collect seed already derived
    generator: WorldGenConfig
    world_path: str  # where its track file is written
    folder: str  # its own sub-folder: driving_log.csv + IMG/
    start: dt.datetime  # time of its first row


@dataclass
class WorldOutcome:
    seed: int
    index: int
    rows: int
    interventions: int
    laps: int
    collect_seed: int
    img_dir: str  # where the worker wrote the frames: every image path of its log starts with it
    track_sha256: str
    causes: dict[str, int] = field(default_factory=dict)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    interrupted: bool = False
    light_intensity: float = 1.0  # the scene light it was collected under (--light-range)


def collect_world(job: WorldJob) -> WorldOutcome:
    """Generate world ``job.seed`` and record the autopilot's laps through it (in a worker)."""
    import cv2

    cv2.setNumThreads(1)
    started = time.perf_counter()
    path = write_world(job.seed, job.world_path, job.generator)
    result = collect(replace(job.collect, track=str(path)), Path(job.folder), overwrite=True, start=job.start)
    if not result.interrupted and result.sim_time_s + 60 >= WORLD_TIME_SLOT.total_seconds():
        raise BadValue(f"world {job.seed}: {result.sim_time_s:.0f} s of driving do not fit the day of simulated "
                         "time each world has (frame names would collide); collect fewer laps per world")
    causes: dict[str, int] = {}
    for lap in result.laps:
        for cause, n in lap.causes().items():
            causes[cause] = causes.get(cause, 0) + n
    return WorldOutcome(job.seed, job.index, result.rows, result.interventions, len(result.laps),
                        job.collect.seed, str(result.out_dir / "IMG"), file_sha256(path), causes,
                        round(result.sim_time_s, 3), round(time.perf_counter() - started, 3), result.interrupted,
                        job.collect.light_intensity)


def collect_world_packed(job: WorldJob) -> tuple[WorldOutcome, dict[str, bytes]]:
    """:func:`collect_world` in a temporary folder of the machine it runs on; the files come back as bytes."""
    with tempfile.TemporaryDirectory(prefix="rbc_world_") as tmp:
        here = replace(job, world_path=str(Path(tmp) / _WORLD_FILE), folder=str(Path(tmp) / _WORLD_FOLDER))
        outcome = collect_world(here)
        files = {p.relative_to(tmp).as_posix(): p.read_bytes() for p in sorted(Path(tmp).rglob("*")) if p.is_file()}
    return outcome, files


def unpack(job: WorldJob, files: dict[str, bytes]) -> None:
    """Write the files of :func:`collect_world_packed` to the job's track file and folder."""
    for name, data in files.items():
        if name == _WORLD_FILE:
            target = Path(job.world_path)
        else:
            target = Path(job.folder) / Path(name).relative_to(_WORLD_FOLDER)
        target.parent.mkdir(parents=True, exist_ok=True)
        write_bytes(target, partial(Path.write_bytes, data=data))


def _init_worker() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def _local(jobs: list[WorldJob], workers: int) -> Generator[tuple[WorldJob, WorldOutcome], None, None]:
    if workers <= 1 or len(jobs) <= 1:
        for job in jobs:
            yield job, collect_world(job)
        return
    pool = ProcessPoolExecutor(max_workers=min(workers, len(jobs)), initializer=_init_worker)
    waiting = iter(jobs)
    running: dict[Future, WorldJob] = {}
    try:
        # at most one world per worker in flight (none queued), so after Ctrl-C no world starts
        for job in itertools.islice(waiting, workers):
            running[pool.submit(collect_world, job)] = job
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                job = running.pop(future)
                yield job, future.result()
                for following in itertools.islice(waiting, 1):
                    running[pool.submit(collect_world, following)] = following
    finally:  # Ctrl-C reaches the workers too: they stop their world (kept out of the journal) and exit
        pool.shutdown(wait=True, cancel_futures=True)


def _ray(jobs: list[WorldJob], workers: int,
         address: str | None) -> Generator[tuple[WorldJob, WorldOutcome], None, None]:
    from tools.ray_support import import_ray, init_ray

    ray = import_ray()
    owns = init_ray(ray, workers, address)
    pending: list = []
    try:
        # a world is deterministic for its seed, so Ray may simply run a lost one again
        remote = ray.remote(num_cpus=1, max_retries=2)(collect_world_packed)
        refs = {remote.remote(job): job for job in jobs}
        pending = list(refs)
        log.info("Ray backend: %d worlds on %d CPUs (%s)", len(jobs), int(ray.cluster_resources().get("CPU", 1)),
                 address or "local instance")
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            job = refs[done[0]]
            outcome, files = ray.get(done[0])
            unpack(job, files)
            yield job, outcome
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if owns:
            ray.shutdown()


def run_jobs(jobs: list[WorldJob], workers: int, backend: str = "local",
             address: str | None = None) -> Generator[tuple[WorldJob, WorldOutcome], None, None]:
    """(job, outcome) of every job, in the order they finish (use with ``contextlib.closing``)."""
    if backend not in BACKENDS:
        raise BadValue(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "ray":
        return _ray(jobs, workers, address)
    if address:
        raise BadValue("--address is the Ray cluster's address; add --backend ray")
    return _local(jobs, workers)
