"""The candidate scores of the monitor study (:mod:`tools.monitoreval.study`): what each model file answers per
frame of a recorded run, and every candidate's one-second score from those answers.

A run's *reference* is the model that the monitor would ship beside (``generalist.onnx``); its *served* model is the
file that drove it: the reference itself, or for a degraded run the reference with seeded weight noise
(:func:`tools.monitoreval.modelfiles.degraded_model`, recreated from the run's sigma and seed).
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drive_server.serving.monitor import FRAMES_PER_SECOND
from models.monitoring.calibrate import window_means
from models.monitoring.ensemble import ensemble_scores
from models.monitoring.failures import FailureRun
from protocol.errors import BadValue
from tools.monitoreval.modelfiles import MIRROR_HALVES, degraded_model, file_digest

log = logging.getLogger(__name__)

MEMBER_SEED = 1000  # seeds of the weight-perturbed ensemble members (the runs' own copies use 500-505)


@dataclass(frozen=True)
class Candidate:
    key: str
    kind: str  # a, b, c or d, as in tools.monitoreval.study's docstring
    label: str


def candidates(others: Sequence[str], halves: bool, members: int, sigma: float) -> list[Candidate]:
    out = [Candidate("carried", "a", "the score of the monitor the reference file carries"),
           Candidate("shift", "a", "shift disagreement of the served model"),
           Candidate("steer_abs", "b", "|steering| (reference)"),
           Candidate("steer_std", "b", "steering std over 1 s (reference)"),
           Candidate("steer_change", "b", "|steering change| per frame (reference)"),
           Candidate("served_abs", "b", "|steering| (served)"),
           Candidate("served_std", "b", "steering std over 1 s (served)"),
           Candidate("served_change", "b", "|steering change| per frame (served)"),
           Candidate("vs_reference", "c", "|served - reference|")]
    if halves:
        out.append(Candidate("vs_unmirrored", "c", "|served - reference's network unmirrored|"))
    out += [Candidate(f"vs_{name}", "c", f"|served - {name}.onnx|") for name in others]
    if others:
        out.append(Candidate("ensemble", "d", f"std of the reference and {', '.join(others)}"))
    if len(others) >= 2:
        out.append(Candidate("ensemble_monitor", "d", "|served - mean of the others| + their std "
                                                      "(rbc monitor fit --score ensemble)"))
        out.append(Candidate("ensemble_spread", "d", "the ensemble monitor's score + the served steering's std over "
                                                     "1 s (both in steering units, unweighted)"))
    if halves:
        out.append(Candidate("mirror", "d", "std of the served model's two mirrored halves"))
    if members:
        out.append(Candidate("perturbed", "d", f"std of the served model and {members} copies with weight noise "
                                               f"{sigma:g}"))
    return out


class _Net:
    """One ONNX graph in its own session: uint8 inputs in, the named outputs per frame out."""

    def __init__(self, graph: bytes, threads: int) -> None:
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.intra_op_num_threads, options.inter_op_num_threads = threads, 1
        options.log_severity_level = 3
        self.session = ort.InferenceSession(graph, options, providers=["CPUExecutionProvider"])
        self.input, *rest = [i.name for i in self.session.get_inputs()]
        self.steering_input = rest[0] if rest else None  # an ensemble monitor's served steering (batch, 1)
        self.outputs = [o.name for o in self.session.get_outputs()]

    def run(self, inputs: np.ndarray, steering: np.ndarray | None = None, batch: int = 256) -> dict[str, np.ndarray]:
        parts: dict[str, list[np.ndarray]] = {name: [] for name in self.outputs}
        for start in range(0, len(inputs), batch):
            x = inputs[start:start + batch].astype(np.float32) / 255.0 - 0.5  # failures.FailureRun.floats
            feed = {self.input: x}
            if self.steering_input is not None:
                assert steering is not None, "a graph that takes the served steering"
                feed[self.steering_input] = np.asarray(steering[start:start + batch], np.float32).reshape(-1, 1)
            for name, value in zip(self.outputs, self.session.run(None, feed), strict=True):
                parts[name].append(np.asarray(value, np.float64).reshape(-1))
        return {name: np.concatenate(v) if v else np.zeros(0) for name, v in parts.items()}


def steering_graph(path: Path) -> tuple[bytes, bool]:
    """The steering graph, with its mirrored halves as extra outputs where it has them (output 0 is the steering)."""
    import onnx
    from onnx import TensorProto, helper

    proto = onnx.load(str(path))
    produced = {name for node in proto.graph.node for name in node.output}
    halves = all(h in produced for h in MIRROR_HALVES)
    if halves:
        proto.graph.output.extend(helper.make_tensor_value_info(h, TensorProto.FLOAT, None) for h in MIRROR_HALVES)
    return proto.SerializeToString(), halves


@dataclass
class Served:
    """What one model file answers per frame: steering, its mirrored halves, shift score, perturbed members."""

    steer: np.ndarray
    halves: tuple[np.ndarray, np.ndarray] | None
    shift: np.ndarray
    members: list[np.ndarray]


class Scorer:
    """The per-frame scores of one model file (and its shift graph and weight-perturbed copies), built once."""

    def __init__(self, path: Path, members: int, sigma: float, scratch: Path, threads: int) -> None:
        from models.monitoring.disagreement import shift_disagreement_graph

        graph, self.has_halves = steering_graph(path)
        self.steer = _Net(graph, threads)
        self.shift = _Net(shift_disagreement_graph(path), threads)
        self.members = [_Net(degraded_model(path, scratch, sigma, MEMBER_SEED + k).read_bytes(), threads)
                        for k in range(members)]

    def __call__(self, inputs: np.ndarray) -> Served:
        out = self.steer.run(inputs)
        steer = out[self.steer.outputs[0]]
        halves = (out[MIRROR_HALVES[0]], out[MIRROR_HALVES[1]]) if self.has_halves else None
        return Served(steer, halves, self.shift.run(inputs)["score"],
                      [m.run(inputs)[m.outputs[0]] for m in self.members])


def window_std(x: np.ndarray, window: int) -> np.ndarray:
    """The standard deviation over the last ``window`` frames at every frame (growing windows at the start)."""
    x = np.asarray(x, np.float64)
    if x.size == 0:
        return x
    c1, c2 = np.concatenate([[0.0], np.cumsum(x)]), np.concatenate([[0.0], np.cumsum(x * x)])
    ends = np.arange(1, x.size + 1)
    starts = np.maximum(0, ends - window)
    n = ends - starts
    mean = (c1[ends] - c1[starts]) / n
    return np.sqrt(np.maximum(0.0, (c2[ends] - c2[starts]) / n - mean * mean))


def _change(x: np.ndarray) -> np.ndarray:
    return np.abs(np.diff(x, prepend=x[:1]))


def window_scores(frame: dict[str, Any], window: int = FRAMES_PER_SECOND) -> dict[str, np.ndarray]:
    """Every candidate's one-second score at every frame of one stretch of driving, from its per-frame answers:
    ``carried``, ``reference`` and ``served`` (:class:`Served`), ``others`` (name -> steering)."""
    ref: Served = frame["reference"]
    served: Served = frame["served"]
    others: dict[str, np.ndarray] = frame["others"]

    def mean(x: np.ndarray) -> np.ndarray:
        return window_means(x, window)

    out = {"carried": mean(frame["carried"]), "shift": mean(served.shift),
           "steer_abs": mean(np.abs(ref.steer)), "steer_std": window_std(ref.steer, window),
           "steer_change": mean(_change(ref.steer)),
           "served_abs": mean(np.abs(served.steer)), "served_std": window_std(served.steer, window),
           "served_change": mean(_change(served.steer)),
           "vs_reference": mean(np.abs(served.steer - ref.steer))}
    if ref.halves is not None:
        out["vs_unmirrored"] = mean(np.abs(served.steer - ref.halves[0]))
    for name, steer in others.items():
        out[f"vs_{name}"] = mean(np.abs(served.steer - steer))
    if others:
        out["ensemble"] = mean(np.std(np.stack([ref.steer, *others.values()]), axis=0))
    if len(others) >= 2:
        out["ensemble_monitor"] = mean(ensemble_scores(served.steer, np.stack(list(others.values()))))
        out["ensemble_spread"] = out["ensemble_monitor"] + out["served_std"]
    if served.halves is not None:
        out["mirror"] = mean(np.abs(served.halves[0] + served.halves[1]) / 2.0)  # std of a and -b
    if served.members:
        out["perturbed"] = mean(np.std(np.stack([served.steer, *served.members]), axis=0))
    return out


def slice_answers(frame: dict[str, Any], a: int, b: int) -> dict[str, Any]:
    """Frames ``a`` to ``b`` of a run's per-frame answers (a calibration lap's stretch)."""
    def cut(s: Served) -> Served:
        return Served(s.steer[a:b], None if s.halves is None else (s.halves[0][a:b], s.halves[1][a:b]),
                      s.shift[a:b], [m[a:b] for m in s.members])

    return {"carried": frame["carried"][a:b], "reference": cut(frame["reference"]),
            "served": cut(frame["served"]), "others": {k: v[a:b] for k, v in frame["others"].items()}}


@dataclass
class Study:
    """Everything one study run needs: the reference model, its monitor, the other same-contract models."""

    model: Path
    members: int = 4
    member_sigma: float = 0.1
    threads: int = 1
    others_folder: Path | None = None
    say: Callable[[str], None] = log.info
    copies: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        from drive_server.serving.model import SteeringModel

        if not self.model.is_file():
            raise BadValue(f"{self.model}: no such model file")
        if self.members < 0 or not 0 < self.member_sigma < 5 or self.threads < 1:
            raise BadValue(f"expected --members >= 0, 0 < --member-sigma < 5, --threads >= 1; got {self.members}, "
                           f"{self.member_sigma:g}, {self.threads}")
        steering = SteeringModel(self.model)
        found = steering.monitor()
        if found is None:
            raise BadValue(f"{self.model.name} carries no monitor: the study scores the one it carries")
        self.contract = steering.contract
        self.digest = file_digest(self.model)
        self.carried = _Net(found[1].model_bytes, self.threads)
        self.others: dict[str, _Net] = {}  # same-contract model files by stem
        self.contracts: dict[str, str] = {}  # every other model file: "same" or its contract
        for path in sorted((self.others_folder or self.model.parent).glob("*.onnx")):
            if path.resolve() == self.model.resolve():
                continue
            contract = SteeringModel(path).contract
            same = contract == self.contract
            self.contracts[path.name] = "same" if same else (
                f"{contract.width}x{contract.height}, crop {contract.crop_top}..{contract.crop_bottom}, "
                f"decode 1/{contract.decode_reduce or 1}")
            if same:
                self.others[path.stem] = _Net(steering_graph(path)[0], self.threads)
        self._scratch = tempfile.TemporaryDirectory(prefix="rbc-study-")
        self.scratch = Path(self._scratch.name)
        self.reference = Scorer(self.model, self.members, self.member_sigma, self.scratch, self.threads)

    def keys(self) -> list[str]:
        return [c.key for c in self.candidates()]

    def candidates(self) -> list[Candidate]:
        return candidates(list(self.others), self.reference.has_halves, self.members, self.member_sigma)

    def served_path(self, run: FailureRun, cache: Path | None) -> Path | None:
        """The file that drove ``run``: None for the reference itself, else its weight-noised copy, recreated."""
        sigma = float(run.meta.get("weight_noise", 0.0) or 0.0)
        if not sigma:
            return None
        if run.meta.get("model_sha256") != self.digest:
            raise BadValue(f"{run.name} was driven by a copy of a model file {run.meta.get('model_sha256')}, not of "
                           f"{self.model.name} ({self.digest}): give that file with --model")
        seed = int(run.meta["seed"])
        path = degraded_model(self.model, self.scratch / "served", sigma, seed)
        cached = cache / path.name if cache is not None else None
        self.copies.append({"run": run.name, "sigma": sigma, "seed": seed, "sha256": file_digest(path),
                            "matches_cached_copy": (file_digest(cached) == file_digest(path))
                            if cached is not None and cached.is_file() else None})
        return path

    def frame_answers(self, run: FailureRun, cache: Path | None = None) -> dict[str, Any]:
        reference = self.reference(run.inputs)
        path = self.served_path(run, cache)
        if path is None:
            served = reference
        else:
            served = Scorer(path, self.members, self.member_sigma, self.scratch, self.threads)(run.inputs)
        carried = self.carried.run(run.inputs, served.steer)[self.carried.outputs[0]]
        return {"carried": carried, "reference": reference, "served": served,
                "others": {k: net.run(run.inputs)[net.outputs[0]] for k, net in self.others.items()}}

    def close(self) -> None:
        self._scratch.cleanup()
