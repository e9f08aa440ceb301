"""One training set over many procedural worlds (``rbc collect --worlds N --world-seed S``).

Each world S..S+N-1 is generated into ``OUT/worlds/world-S.json`` and driven by the autopilot in its
own sub-folder of ``OUT/.partial/`` (in worker processes or Ray tasks), with a collect seed derived
from ``--seed`` and the world seed, and its own day of simulated time so frame names never collide.
A finished world is journaled there (``done.json``). When all are done the driver moves the frames
into ``OUT/IMG/``, writes ``OUT/worlds.csv`` (the world, rows, frames and track file of every row)
and renames ``OUT/driving_log.csv`` into place last, so an interrupted collection never leaves a
log, and ``resume=True`` continues with the worlds not journaled yet. The log is the 7-column
Udacity log every reader takes; the record of worlds is a sidecar file, not an extra column.
The output depends on the arguments only, never on the number of workers or the backend.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import logging
import math
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from protocol.datalog_writer import IMAGE_DIR, LOG_NAME
from protocol.errors import BadValue
from protocol.rigfile import write_rig
from protocol.runrecords import atomic_path, read_json, write_json, write_text
from tools.sim.collect.backends import WORLD_TIME_SLOT, WorldJob, WorldOutcome, run_jobs
from tools.sim.collect.dataset import EPOCH, CollectConfig, OutputDirError
from tools.sim.worldgen import GENERATOR_VERSION, WorldGenConfig, seed_range_of, world_seed_range
from tools.sim.worldgen.config import seed_label

log = logging.getLogger(__name__)

PARTIAL = ".partial"  # worlds in progress and the journal of finished ones
WORLDS_DIR = "worlds"
WORLDS_CSV = "worlds.csv"
MAX_WORLDS = 100_000
#: worlds.csv: one line per world; rows are 1-based line numbers of driving_log.csv, images centre frames
WORLDS_COLUMNS = ("world_seed", "seed_range", "first_row", "last_row", "rows", "first_image", "last_image",
                  "interventions", "collect_seed", "track_file", "track_sha256", "generator_version",
                  "light_intensity")
#: the random stream of a world's light intensity (--light-range), apart from its autopilot's
LIGHT_STREAM = 1


def training_seed_problem(first: int, count: int) -> str | None:
    """Why seeds first..first+count-1 may not be trained on (None: all are training worlds)."""
    train = world_seed_range("train")
    last = first + count - 1
    outside = next((s for s in (first, last) if s not in train), None)  # the range is contiguous
    if outside is None:
        return None
    return (f"world seeds {first}-{last} are not all training worlds (seed {outside} is {seed_label(outside)}; "
            f"training worlds are {train.start:,}-{train.stop - 1:,}): held-out worlds must never be trained on")


def light_range_problem(lo: float, hi: float) -> str | None:
    """Why ``lo``..``hi`` is not a range of light intensities to draw from (None: it is)."""
    if not 0 < lo <= hi < math.inf:
        return f"expected LO:HI with 0 < LO <= HI, e.g. 0.5:2, got {lo:g}:{hi:g}"
    return None


@dataclass(frozen=True)
class WorldsConfig:
    first_seed: int = 0
    count: int = 1
    allow_eval_worlds: bool = False  # seeds outside the training range only when explicitly asked for
    generator: WorldGenConfig = field(default_factory=WorldGenConfig)
    #: domain randomisation of the sun: each world's light intensity drawn log-uniformly from this range
    #: (None: every world at the collect config's light intensity)
    light_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        problem = light_range_problem(*self.light_range) if self.light_range is not None else None
        if problem:
            raise BadValue(f"--light-range: {problem}")
        if not 1 <= self.count <= MAX_WORLDS:
            raise BadValue(f"--worlds must be 1..{MAX_WORLDS}, got {self.count}")
        if self.first_seed < 0:
            raise BadValue(f"--world-seed must be >= 0, got {self.first_seed}")
        problem = training_seed_problem(self.first_seed, self.count)
        if problem and not self.allow_eval_worlds:
            raise BadValue(problem)

    @property
    def seeds(self) -> list[int]:
        return list(range(self.first_seed, self.first_seed + self.count))


def world_collect_seed(seed: int, world_seed: int) -> int:
    """The autopilot and camera seed of one world: distinct per world, a function of the two seeds only."""
    return int(np.random.SeedSequence([seed, world_seed]).generate_state(1)[0]) >> 1


def world_light_intensity(seed: int, world_seed: int, light_range: tuple[float, float]) -> float:
    """A world's light intensity under ``--light-range``: log-uniform (as many worlds darker as brighter by
    the same factor), a function of the collect seed and the world seed only (not of workers or order)."""
    lo, hi = light_range
    u = np.random.default_rng([seed, world_seed, LIGHT_STREAM]).uniform()
    return round(float(np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo)))), 4)


@dataclass
class WorldsResult:
    out_dir: Path
    total: int
    outcomes: list[WorldOutcome] = field(default_factory=list)  # finished worlds, in seed order
    resumed: int = 0  # worlds journaled by an earlier, interrupted run
    interrupted: bool = False
    wall_time_s: float = 0.0

    @property
    def rows(self) -> int:
        return sum(o.rows for o in self.outcomes)

    @property
    def interventions(self) -> int:
        return sum(o.interventions for o in self.outcomes)


def _prepare(out: Path, plan: dict, overwrite: bool, resume: bool) -> Path:
    partial = out / PARTIAL
    if overwrite and resume:
        raise BadValue("choose --overwrite or --resume, not both")
    out.mkdir(parents=True, exist_ok=True)
    if overwrite:
        for name in (LOG_NAME, WORLDS_CSV):
            (out / name).unlink(missing_ok=True)
        for name in (IMAGE_DIR, WORLDS_DIR, PARTIAL):
            shutil.rmtree(out / name, ignore_errors=True)
    elif not (resume and partial.is_dir()) and any(out.iterdir()):
        if resume and (out / LOG_NAME).is_file():
            raise OutputDirError(f"{out} holds a finished collection: nothing to resume")
        raise OutputDirError(f"{out} is not empty; pass --overwrite to replace it, or --resume to continue an "
                             "interrupted collection of the same worlds")
    plan_file = partial / "plan.json"
    if resume and plan_file.is_file():
        earlier = read_json(plan_file)
        if earlier != plan:
            diff = sorted(k for k in plan if earlier.get(k) != plan[k])
            raise OutputDirError(f"--resume: {out} was started with other {', '.join(diff)} arguments; "
                                 "use the same command, or --overwrite to start afresh")
    write_json(plan_file, plan)
    return partial


def _outcome(path: Path) -> WorldOutcome | None:
    try:
        return WorldOutcome(**json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError, TypeError):
        return None


def collect_worlds(config: CollectConfig, worlds: WorldsConfig, out_dir: Path, workers: int = 1,
                   backend: str = "local", address: str | None = None, overwrite: bool = False,
                   resume: bool = False, on_world: Callable[[WorldOutcome, int, int], None] | None = None
                   ) -> WorldsResult:
    """Collect every world of ``worlds`` with ``config`` (its track ignored) into one data set in ``out_dir``.

    ``on_world(outcome, done, total)`` is told of every finished world, in the order they finish.
    """
    started = time.perf_counter()
    out = Path(out_dir).resolve()
    plan = {"collect": asdict(replace(config, track="")), "worlds": asdict(worlds),
            "generator_version": GENERATOR_VERSION}
    partial = _prepare(out, json.loads(json.dumps(plan)), overwrite, resume)
    write_rig(out, config.camera)  # before any frame: rbc train reads which camera they are
    result = WorldsResult(out, worlds.count)
    finished: dict[int, WorldOutcome] = {}
    jobs = []
    for index, seed in enumerate(worlds.seeds):
        folder = partial / f"world-{seed}"
        done = _outcome(folder / "done.json") if resume else None
        if done is not None and (out / WORLDS_DIR / f"world-{seed}.json").is_file():
            finished[seed] = done
            continue
        light = (world_light_intensity(config.seed, seed, worlds.light_range) if worlds.light_range
                 else config.light_intensity)
        world_config = replace(config, seed=world_collect_seed(config.seed, seed), light_intensity=light)
        jobs.append(WorldJob(index, seed, world_config,
                             worlds.generator, str(out / WORLDS_DIR / f"world-{seed}.json"), str(folder),
                             EPOCH + index * WORLD_TIME_SLOT))
    result.resumed = len(finished)
    if finished:
        log.info("resuming: %d of %d worlds already collected", len(finished), worlds.count)
    try:
        with contextlib.closing(run_jobs(jobs, workers, backend, address)) as outcomes:
            for job, outcome in outcomes:
                if outcome.interrupted:  # Ctrl-C reached the worker first: not a finished world
                    raise KeyboardInterrupt
                write_json(Path(job.folder) / "done.json", asdict(outcome))
                finished[job.seed] = outcome
                if on_world is not None:
                    on_world(outcome, len(finished), worlds.count)
    except KeyboardInterrupt:
        result.interrupted = True
    result.outcomes = [finished[s] for s in worlds.seeds if s in finished]
    if result.interrupted:
        log.warning("interrupted: %d of %d worlds collected in %s; the same command with --resume continues",
                    len(finished), worlds.count, partial)
    else:
        assemble(out, result.outcomes)
    result.wall_time_s = time.perf_counter() - started
    return result


def assemble(out: Path, outcomes: list[WorldOutcome]) -> Path:
    """Move the worlds' frames into ``out/IMG``, write worlds.csv, then the log (last, atomically).

    Safe to repeat after an interruption: frames already moved are found in place.
    """
    partial, img = out / PARTIAL, out / IMAGE_DIR
    img.mkdir(exist_ok=True)
    new = str(img) + os.sep
    table = io.StringIO()
    writer = csv.writer(table, lineterminator="\n")
    writer.writerow(WORLDS_COLUMNS)
    line = 0
    with atomic_path(out / LOG_NAME) as tmp, tmp.open("w", encoding="utf-8", newline="") as fh:
        for o in outcomes:
            folder = partial / f"world-{o.seed}"
            old = o.img_dir + os.sep
            rows = [r.replace(old, new) for r in (folder / LOG_NAME).read_text(encoding="utf-8").splitlines()]
            for row in rows:
                name = row[len(new):].split(", ", 1)[0]
                if not row.startswith(new) or not ((img / name).is_file() or (folder / IMAGE_DIR / name).is_file()):
                    raise RuntimeError(f"{folder}: row {row[:80]!r} does not name a frame of this world")
            for frame in sorted((folder / IMAGE_DIR).glob("*")) if (folder / IMAGE_DIR).is_dir() else []:
                os.replace(frame, img / frame.name)
            fh.writelines(r + "\n" for r in rows)
            names = [r[len(new):].split(", ", 1)[0] for r in (rows[0], rows[-1])] if rows else ["", ""]
            writer.writerow([o.seed, seed_range_of(o.seed) or "none", line + 1 if rows else "",
                             line + len(rows) if rows else "", len(rows), *names, o.interventions, o.collect_seed,
                             f"{WORLDS_DIR}/world-{o.seed}.json", o.track_sha256, GENERATOR_VERSION,
                             f"{o.light_intensity:g}"])
            line += len(rows)
        write_text(out / WORLDS_CSV, table.getvalue())
    shutil.rmtree(partial, ignore_errors=True)
    return out / LOG_NAME
