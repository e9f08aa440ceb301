"""One round's data: drive ``rbc/Drive-v0`` on training worlds, label every visited frame with the expert.

Each step the expert (the autopilot's pure-pursuit steering, ``info["expert_action"]``) drives with probability
beta and the learner (the previous round's ONNX model through drive_server's pipeline, :class:`OnnxPolicy`)
otherwise; either way the frame is recorded with the expert's steering as its label (the mixing and labelling
are :class:`tools.dagger.mixing.ExpertMixing`, a Gymnasium wrapper; one stream of its draws per round, one draw a
step, seeded [seed, round, STREAM_MIX]). A take-over does not end the episode (``terminate_on_takeover=False``):
the referee puts the car back and the learner drives on, so the states after its mistakes are labelled too.
Episodes start anywhere along a new training world (its seed drawn from the training range; the environment
refuses evaluation worlds) and last ``episode_steps`` steps.

The folder is a recording as ``rbc collect`` writes one, so ``rbc train`` reads it unchanged:
``driving_log.csv`` (steering = the expert's label, throttle and brake as applied, speed in mph), ``IMG/`` (the
frames' JPEG bytes exactly as the wire carries them), ``camera_rig.json``, and beside them ``frames.csv``: for
every row the episode, world, who drove, the expert's and the learner's steering and the take-over, if any.
It is written into ``DIR.partial`` and renamed to ``DIR`` when whole, so a killed round leaves no half recording.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import logging
import shutil
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from drive_server.serving.control import ControlLaw
from protocol.datalog_writer import IMAGE_DIR, LOG_NAME, LogWriter, frame_name
from protocol.errors import BadValue
from protocol.facts import CAMERAS
from protocol.rigfile import write_rig
from protocol.runrecords import write_json
from protocol.units import from_kmh
from tools.dagger.config import STREAM_EPISODES, STREAM_MIX, DaggerConfig
from tools.sim.collect.dataset import EPOCH
from tools.sim.worldgen import world_seed_range

if TYPE_CHECKING:
    import gymnasium as gym

    from tools.dagger.mixing import ExpertMixing
    from tools.dagger.records import CollectionRecord
    from tools.envs import OnnxPolicy
    from tools.envs.policy import Observation

log = logging.getLogger(__name__)

FRAMES_CSV = "frames.csv"
FRAMES_COLUMNS = ("row", "episode", "step", "world_seed", "driver", "expert_steering", "learner_steering",
                  "cte_m", "speed_kmh", "intervention")
SUMMARY = "collection.json"


@dataclass(frozen=True)
class Episode:
    """Where one episode drives: a training world and the seed of its reset (spawn point, spawn noise, bumps)."""

    world_seed: int
    reset_seed: int


@dataclass
class CollectionStats:
    frames: int = 0
    episodes: int = 0
    expert_steps: int = 0  # steps the expert drove
    learner_steps: int = 0  # steps the learner drove
    takeovers: int = 0  # take-overs while collecting (the referee put the car back)
    abs_disagreement: float = 0.0  # mean |learner - expert| steering over the steps the learner was asked
    world_seeds: tuple[int, ...] = ()

    def as_record(self) -> CollectionRecord:
        """The stats as a round's record keeps them (every field, the seeds as a list)."""
        return {"frames": self.frames, "episodes": self.episodes, "expert_steps": self.expert_steps,
                "learner_steps": self.learner_steps, "takeovers": self.takeovers,
                "abs_disagreement": self.abs_disagreement, "world_seeds": list(self.world_seeds)}


def episodes(config: DaggerConfig, round_: int, count: int) -> list[Episode]:
    """The first ``count`` episodes of a round: seeded by (seed, round), the same in "dagger" and "bc"."""
    rng = np.random.default_rng([config.seed, round_, STREAM_EPISODES])
    train = world_seed_range("train")
    return [Episode(int(rng.integers(train.start, train.stop)), int(rng.integers(1, 2**31 - 1)))
            for _ in range(count)]


def collect_round(config: DaggerConfig, round_: int, out: Path, learner: Path | None,
                  progress: Callable[[int, int], None] | None = None) -> CollectionStats:
    """Record round ``round_``'s ``config.new_frames(round_)`` expert-labelled frames into ``out``.

    ``learner``: the ONNX model that drives with probability 1 - beta (None only where beta is 1).
    ``progress(frames, total)`` is called after every episode.
    """
    from tools.dagger.mixing import AskedCommand, ExpertMixing
    from tools.envs import OnnxPolicy

    beta = config.beta(round_)
    if learner is None and beta < 1.0:
        raise BadValue(f"round {round_} mixes in a learner (beta {beta:g}) but none was given")
    total = config.new_frames(round_)
    plan = episodes(config, round_, -(-total // config.episode_steps))
    law = ControlLaw(speed_limit_kmh=config.speed_limit_kmh)  # Eq. 14 of the environment and of the learner
    policy = OnnxPolicy(learner, law=law) if learner is not None else None
    if policy is not None and policy.camera_rig != config.camera:
        raise BadValue(f"the learner {learner} was trained on the {policy.camera_rig} camera, the data is "
                       f"recorded with {config.camera}")
    mix = np.random.default_rng([config.seed, round_, STREAM_MIX])  # one stream of decisions across the episodes
    final = out.resolve()  # the log names each frame where it will be once the folder is renamed into place
    partial = final.with_name(final.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)  # what a killed collection left: collected again, the same
    (partial / IMAGE_DIR).mkdir(parents=True)
    write_rig(partial, config.camera)
    with LogWriter(partial / LOG_NAME) as writer:
        recorder = _Recorder(partial, final, writer, EPOCH + dt.timedelta(days=round_), total)
        for number, episode in enumerate(plan):
            env = ExpertMixing(AskedCommand(_make_env(config, episode, law)), beta, rng=mix)
            try:
                hz = float(env.get_wrapper_attr("config").control_hz)
                _drive_episode(env, policy, config, number, episode, hz, recorder)
            finally:
                env.close()
            recorder.clock += config.episode_steps / hz + 10.0  # a pause: a new session
            stats = recorder.stats
            stats.episodes += 1
            stats.world_seeds += (episode.world_seed,)
            if progress is not None:
                progress(stats.frames, total)
            if stats.frames >= total:
                break
    stats = recorder.stats
    if stats.frames != total:
        raise RuntimeError(f"round {round_}: {stats.frames} frames collected, {total} planned")
    stats.abs_disagreement = float(np.mean(recorder.disagreements)) if recorder.disagreements else 0.0
    (partial / FRAMES_CSV).write_text(recorder.table.getvalue(), encoding="utf-8")
    write_json(partial / SUMMARY, {"round": round_, "beta": beta, "learner": str(learner) if learner else None,
                                   **asdict(stats)})
    shutil.rmtree(final, ignore_errors=True)
    partial.rename(final)
    return stats


def _make_env(config: DaggerConfig, episode: Episode, law: ControlLaw) -> gym.Env[Observation, np.ndarray]:
    """``rbc/Drive-v0`` on the episode's training world; a take-over puts the car back and the episode goes on."""
    import gymnasium

    from tools.envs import ENV_ID

    return gymnasium.make(ENV_ID, world_seed=episode.world_seed, purpose="train", spawn="random",
                          cameras=config.cameras, camera=config.camera, law=law, action_delay=config.action_delay,
                          max_episode_steps=config.episode_steps, terminate_on_takeover=False,
                          disable_env_checker=True)


@dataclass
class _Recorder:
    """Where a round's frames go: the frames and the driving log, ``frames.csv``'s rows, the statistics."""

    partial: Path
    final: Path
    writer: LogWriter
    start: dt.datetime
    total: int
    clock: float = 0.0  # seconds from ``start`` to the episode's first frame
    stats: CollectionStats = field(default_factory=CollectionStats)
    disagreements: list[float] = field(default_factory=list)
    table: io.StringIO = field(default_factory=io.StringIO)

    def __post_init__(self) -> None:
        self.rows = csv.writer(self.table, lineterminator="\n")
        self.rows.writerow(FRAMES_COLUMNS)


def _drive_episode(env: ExpertMixing[Observation], policy: OnnxPolicy | None, config: DaggerConfig, number: int,
                   episode: Episode, hz: float, recorder: _Recorder) -> None:
    """One episode: the learner (when there is one) is asked every step, the wrapper decides who drives and
    labels the frame; the frame, its label and what happened are recorded."""
    cameras = CAMERAS[:config.cameras]
    stats = recorder.stats
    obs, info = env.reset(seed=episode.reset_seed)
    for step in range(config.episode_steps):
        if stats.frames >= recorder.total:
            break
        learned = policy.steering(obs["center"] if config.cameras == 3 else obs, info) if policy else None
        when = recorder.start + dt.timedelta(seconds=round(recorder.clock + step / hz, 3))
        paths = _write_frames(recorder.partial / IMAGE_DIR, cameras, when, obs, info)
        speed_mph = from_kmh(info["speed_kmh"], "mph")
        obs, _, _, truncated, info = env.step(None if learned is None else np.array([learned], np.float32))
        done = env.last
        assert done is not None  # set by the step
        expert, throttle = float(done.label[0]), info["command"].throttle
        recorder.writer.write([str(recorder.final / IMAGE_DIR / p.name) for p in paths], expert,
                              max(0.0, throttle), max(0.0, -throttle), speed_mph)
        stats.frames += 1
        stats.expert_steps += done.by_expert
        stats.learner_steps += not done.by_expert
        stats.takeovers += bool(info["intervention"])
        if learned is not None:
            recorder.disagreements.append(abs(learned - expert))
        recorder.rows.writerow([stats.frames, number, step, episode.world_seed,
                                "expert" if done.by_expert else "learner", f"{expert:.7g}",
                                "" if learned is None else f"{learned:.7g}", f"{info['cte_m']:.4f}",
                                f"{info['speed_kmh']:.3f}", info["intervention"]])
        if truncated:
            break


def _write_frames(folder: Path, cameras: tuple[str, ...], when: dt.datetime, obs, info) -> list[Path]:
    """The step's frames as JPEG files: the centre one as the wire carries it (``info["jpeg"]``), side ones
    encoded from the observation at the simulator's quality."""
    paths = [folder / frame_name(camera, when) for camera in cameras]
    if len(cameras) == 1:
        paths[0].write_bytes(info["jpeg"])
        return paths
    from protocol.facts import JPEG_QUALITY
    from protocol.jpeg import encode_jpeg

    for camera, path in zip(cameras, paths, strict=True):
        path.write_bytes(info["jpeg"] if camera == "center" else encode_jpeg(obs[camera], JPEG_QUALITY))
    return paths


def read_stats(folder: Path) -> CollectionStats:
    """The statistics a finished collection wrote beside its frames."""
    from protocol.runrecords import read_json

    data = read_json(folder / SUMMARY)
    known = {k: v for k, v in data.items() if k in CollectionStats.__dataclass_fields__ and k != "world_seeds"}
    return CollectionStats(**known, world_seeds=tuple(data.get("world_seeds", ())))
