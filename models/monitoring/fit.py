"""``rbc monitor fit``'s work: train the score (the autoencoder on nominal frames, or the failure predictor on
runs that failed) or build it (shift; ensemble, from members trained elsewhere), calibrate it on other nominal
runs, and write the steering model's file with the monitor attached."""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drive_server.serving.contract import PreprocessContract
from drive_server.serving.model import SteeringModel
from drive_server.serving.monitor import FRAME, FRAMES_PER_SECOND, STEERING, MonitorSpec
from models.monitoring.attach import attach_monitor
from models.monitoring.autoencoder import SCORE_NAME as AUTOENCODER
from models.monitoring.autoencoder import export_score_graph, train_autoencoder
from models.monitoring.calibrate import calibrate
from models.monitoring.disagreement import SCORE_NAME as SHIFT
from models.monitoring.disagreement import SHIFT_PIXELS, graph_scores, shift_disagreement_graph
from models.monitoring.ensemble import SCORE_NAME as ENSEMBLE
from models.monitoring.ensemble import check_ensemble_members, ensemble_score_graph, network_outputs
from models.monitoring.failures import LabelRules, labels, load_meta, load_run, run_files
from models.monitoring.frames import iter_runs, load_runs
from models.monitoring.framestats import SCORE_NAME as FRAMESTATS
from models.monitoring.framestats import combine_scores, fit_features, frame_features, framestats_graph
from models.monitoring.mcdropout import DEFAULT_SAMPLES, dropout_members, dropout_rate
from models.monitoring.mcdropout import SCORE_NAME as MCDROPOUT
from models.monitoring.predictor import SCORE_NAME as PREDICTOR
from models.monitoring.predictor import train_predictor
from protocol.errors import BadValue

log = logging.getLogger(__name__)

#: The scores ``rbc monitor fit`` can attach (``keep``: the model file's own monitor, calibrated afresh).
KEEP = "keep"
SCORES = (AUTOENCODER, SHIFT, PREDICTOR, ENSEMBLE, MCDROPOUT, FRAMESTATS, KEEP)


@dataclass(frozen=True)
class FitPlan:
    """What to fit: the defaults are defined here once; ``rbc monitor fit``'s flags read them."""

    model: Path
    out: Path
    train: tuple[Path, ...]
    calibration: tuple[Path, ...]
    # or "shift": the model's disagreement with itself on a moved frame (no training); "predictor": a network that
    # learns from runs that failed (rbc monitor failures) how likely a failure is within a few seconds; or "keep":
    # the monitor the model file already carries, calibrated afresh (another target rate, other nominal driving);
    # "ensemble": the served steering against ``members``, other networks of the model's recipe (no training here)
    # "framestats": the frame's brightness and contrast against nominal frames' (--data; models.monitoring.framestats)
    score: str = AUTOENCODER
    members: tuple[Path, ...] = ()
    # "mcdropout": the served network sampled with fixed dropout masks, as members (models.monitoring.mcdropout)
    samples: int = DEFAULT_SAMPLES
    # also the frame statistics beside the score (fitted on ``train``): the larger of the two, each in units of its
    # own alarm threshold, so that either can warn (the ensemble is blind to washed-out frames, see framestats)
    with_framestats: bool = False
    epochs: int = 6
    stride: int = 2  # every 2nd training frame: neighbours at 15 Hz are near copies
    seed: int = 0
    window: int = FRAMES_PER_SECOND
    warnings_per_hour: float = 10.0
    alarms_per_hour: float = 1.0

    def __post_init__(self) -> None:
        overlap = {p.resolve() for p in self.train} & {p.resolve() for p in self.calibration}
        if overlap:
            raise BadValue(f"calibration data must be other runs than the training data; both have "
                           f"{', '.join(sorted(str(p) for p in overlap))}")
        if self.score not in SCORES:
            raise BadValue(f"unknown score {self.score!r}; choose one of {', '.join(SCORES)}")
        if (self.score in (AUTOENCODER, PREDICTOR, FRAMESTATS) and not self.train) or not self.calibration:
            raise BadValue("give calibration data (--calibration), and for the autoencoder, the predictor and the "
                           "frame statistics training data (--data)")
        if self.with_framestats and (self.score in (FRAMESTATS, PREDICTOR) or not self.train):
            raise BadValue("--with-framestats goes beside the autoencoder, shift, ensemble or MC-dropout score (or "
                           "the one the file keeps), with nominal frames to fit it on (--data)")
        if self.members and self.score != ENSEMBLE:
            raise BadValue(f"members (--member) are for --score {ENSEMBLE}, not {self.score}")
        if self.samples < 2:
            raise BadValue(f"MC-dropout needs at least 2 samples (--samples), got {self.samples}")
        if self.epochs < 1 or self.stride < 1:
            raise BadValue(f"epochs and stride must be >= 1, got {self.epochs} and {self.stride}")


@dataclass
class FitResult:
    spec: MonitorSpec
    train_frames: int
    info: dict[str, Any] = field(default_factory=dict)


def fit_monitor(plan: FitPlan, say: Callable[[str], None] = log.info) -> FitResult:
    contract = SteeringModel(plan.model).contract
    record: dict[str, Any] = {"score": plan.score, "seed": plan.seed}
    inputs: tuple[str, ...] = (FRAME,)
    if plan.score == AUTOENCODER:
        say(f"reading training frames from {len(plan.train)} folder(s) (every {plan.stride}. frame)")
        train = np.concatenate(load_runs(list(plan.train), contract, plan.stride,
                                         progress=lambda d, t: _every_tenth(say, d, t)))
        say(f"training the autoencoder on {len(train):,} frames, {plan.epochs} epochs")
        model = train_autoencoder(train, contract, epochs=plan.epochs, seed=plan.seed,
                                  progress=lambda e, n, loss: say(f"  epoch {e}/{n}: reconstruction error {loss:.5f}"))
        graph = export_score_graph(model, contract)
        record |= {"train_frames": int(len(train)), "train": [p.name for p in plan.train], "epochs": plan.epochs}
    elif plan.score == PREDICTOR:
        frames, targets, runs_used = _failure_frames(plan, say)
        say(f"training the failure predictor on {len(frames):,} frames ({int(targets.sum()):,} within "
            f"{LabelRules().horizon_s:g} s of a failure) from {runs_used} runs, {plan.epochs} epochs")
        predictor = train_predictor(frames, targets, contract, epochs=plan.epochs, seed=plan.seed,
                                    progress=lambda e, n, loss: say(f"  epoch {e}/{n}: loss {loss:.4f}"))
        graph = export_score_graph(predictor, contract)
        record |= {"train_frames": int(len(frames)), "train_positives": int(targets.sum()), "train_runs": runs_used,
                   "train": [p.name for p in plan.train], "epochs": plan.epochs,
                   "labels": {"horizon_s": LabelRules().horizon_s, "quiet_s": LabelRules().quiet_s,
                              "settle_s": LabelRules().settle_s}}
    elif plan.score == SHIFT:
        graph = shift_disagreement_graph(plan.model)
        record |= {"shift_pixels": SHIFT_PIXELS}
    elif plan.score == FRAMESTATS:
        graph = _framestats(plan, contract, say, record)
    elif plan.score == ENSEMBLE:
        members = check_ensemble_members(plan.model, plan.members)
        say(f"building the ensemble monitor of {len(members)} members")
        graph = ensemble_score_graph(plan.model, plan.members)
        inputs = (FRAME, STEERING)
        record |= {"members": members, "spread": True}
    elif plan.score == MCDROPOUT:
        rate = dropout_rate(plan.model)
        say(f"building the MC-dropout monitor: {plan.samples} fixed masks at the network's dropout rate {rate:g}")
        with tempfile.TemporaryDirectory(prefix="rbc_mcdropout_") as tmp:
            samples = dropout_members(plan.model, Path(tmp), plan.samples, seed=plan.seed)
            graph = ensemble_score_graph(plan.model, samples)
        inputs = (FRAME, STEERING)
        record |= {"samples": plan.samples, "dropout": rate, "spread": True}
    else:
        found = SteeringModel(plan.model).monitor()
        if found is None:
            raise BadValue(f"{plan.model.name} carries no monitor to calibrate afresh (--score keep)")
        old, graph_obj = found
        if plan.with_framestats and FRAMESTATS in old.score.split("+"):
            raise BadValue(f"{plan.model.name}'s monitor ({old.score}) has the frame statistics already: "
                           "--score keep without --with-framestats calibrates it afresh")
        graph, inputs = graph_obj.model_bytes, old.inputs
        kept = {k: v for k, v in old.calibration.items() if k in ("train_frames", "train", "epochs", "shift_pixels",
                                                                 "seed", "members", "spread", "samples", "dropout")}
        record |= {**kept, "score": old.score, "recalibrated": True}
    say(f"scoring the calibration runs from {len(plan.calibration)} folder(s)")
    second = _framestats(plan, contract, say, record) if plan.with_framestats else None
    if STEERING in inputs:  # the steering the server would feed: the served network's own, on the same frames
        say("running the served model beside the monitor on the calibration frames")
    scores, second_scores = [], []
    for run in _calibration_inputs(plan, contract, say):  # one run in memory at a time
        steering = network_outputs(plan.model, run) if STEERING in inputs else None
        scores.append(graph_scores(graph, run, steering=steering))
        if second is not None:
            second_scores.append(graph_scores(second, run))
    if second is not None:
        first_alarm = calibrate(scores, plan.window, plan.warnings_per_hour, plan.alarms_per_hour).alarm
        second_alarm = calibrate(second_scores, plan.window, plan.warnings_per_hour, plan.alarms_per_hour).alarm
        say(f"combined with the frame statistics: each part divided by its own alarm threshold "
            f"({first_alarm:.4g} and {second_alarm:.4g}), the larger one")
        graph = combine_scores(graph, second, (first_alarm, second_alarm))
        record |= {"score": f"{record['score']}+{FRAMESTATS}",
                   "parts": [{"score": str(record["score"]), "alarm": first_alarm},
                             {"score": FRAMESTATS, "alarm": second_alarm}]}
        # what the combined graph answers (tests/test_monitor_framestats.py), from the parts' scores at hand rather
        # than running every member over the calibration frames again
        scores = [np.maximum(a / first_alarm, b / second_alarm) for a, b in zip(scores, second_scores, strict=True)]
    cal = calibrate(scores, plan.window, plan.warnings_per_hour, plan.alarms_per_hour,
                    source=", ".join(p.name for p in plan.calibration))
    record = {**cal.record, **record}
    spec = MonitorSpec(str(record["score"]), cal.warn, cal.alarm, plan.window, record, inputs)
    attach_monitor(plan.model, plan.out, spec, graph)
    return FitResult(spec, int(record.get("train_frames", 0)), record)


def _calibration_inputs(plan: FitPlan, contract: PreprocessContract,
                        say: Callable[[str], None]) -> Iterator[np.ndarray]:
    """One input array per calibration run, one at a time: recorded logs read as the server reads them, or the
    model's own nominal runs of rbc monitor failures --set calibration (folders of run files; nominal runs only)."""
    logs = [p for p in plan.calibration if not (Path(p).is_dir() and any(Path(p).glob("*.npz")))]
    runs = iter_runs(logs, contract, 1, progress=lambda d, t: _every_tenth(say, d, t)) if logs else iter(())
    driven = [p for p in plan.calibration if p not in logs]
    files = run_files(driven) if driven else []
    for path in files:  # refused before any work
        meta = load_meta(path)
        if meta.get("group") != "nominal" or meta.get("seed_range", "train") != "train":
            raise BadValue(f"{path}: calibration takes nominal driving on training worlds only")
    return _then_driven(runs, files)


def _then_driven(logged: Iterator[np.ndarray], files: list[Path]) -> Iterator[np.ndarray]:
    yield from logged
    for path in files:
        run = load_run(path)
        yield from _uneventful(run.floats(), run.t, run.takeovers)


#: Around a take-over in a calibration run the driving is not nominal: the 10 s before it (the benchmark's own
#: horizon: a warning there foresaw a real failure) and the 4 s after it (the car was just put back).
BEFORE_TAKEOVER_S, AFTER_TAKEOVER_S = 10.0, 4.0


def _uneventful(x: np.ndarray, t: np.ndarray, takeovers: tuple[tuple[float, str], ...]) -> list[np.ndarray]:
    """The stretches of a driven run away from its take-overs, each a run of its own for the one-second means."""
    keep = np.ones(len(t), bool)
    for when, _ in takeovers:
        keep &= ~((t > when - BEFORE_TAKEOVER_S) & (t < when + AFTER_TAKEOVER_S))
    edges = np.flatnonzero(np.diff(np.r_[0, keep.astype(np.int8), 0]))
    return [x[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True) if b > a]


def _failure_frames(plan: FitPlan, say: Callable[[str], None]) -> tuple[np.ndarray, np.ndarray, int]:
    """The labelled frames of the failure runs in ``plan.train``: every frame before a failure, every
    ``plan.stride``-th of the others; runs on held-out worlds are refused."""
    files = run_files(plan.train)
    say(f"reading {len(files)} failure runs")
    xs, ys = [], []
    for k, path in enumerate(files):
        run = load_run(path)
        if run.meta.get("seed_range", "train") != "train":
            raise BadValue(f"{path}: a run on an evaluation world: the predictor never trains on held-out worlds")
        y = labels(run.t, run.takeovers)
        keep = np.flatnonzero((y == 1) | ((y == 0) & (np.arange(len(y)) % plan.stride == 0)))
        xs.append(run.inputs[keep])
        ys.append(y[keep])
        if (k + 1) % 20 == 0:
            say(f"  {k + 1} of {len(files)} runs")
    return np.concatenate(xs), np.concatenate(ys).astype(np.int8), len(files)


def _framestats(plan: FitPlan, contract: PreprocessContract, say: Callable[[str], None], record: dict) -> bytes:
    """The frame-statistics graph fitted on ``plan.train``'s frames (every ``plan.stride``-th); notes in ``record``."""
    import onnx

    say(f"reading nominal frames for the frame statistics from {len(plan.train)} folder(s) (every {plan.stride}. "
        f"frame)")
    features = np.concatenate([frame_features(run, contract) for run in iter_runs(
        list(plan.train), contract, plan.stride, progress=lambda d, t: _every_tenth(say, d, t))])
    mu, whiten = fit_features(features)
    served = onnx.load(str(plan.model))
    opset = max(o.version for o in served.opset_import if o.domain in ("", "ai.onnx"))
    # beside another score, the other's training folders keep the name "train"
    record |= {"framestats_frames": int(len(features)),
               "framestats_train" if plan.with_framestats else "train": [p.name for p in plan.train]}
    return framestats_graph(contract, mu, whiten, opset=opset, ir_version=served.ir_version)


def _every_tenth(say: Callable[[str], None], done: int, total: int) -> None:
    """Progress with its total, about ten lines per phase."""
    if done % max(1000, (total // 10000 + 1) * 1000) == 0 or done == total:
        say(f"  {done:,} of {total:,} frames")
