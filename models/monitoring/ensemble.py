"""The ensemble monitor: how far the served network's steering is from what other networks of its recipe answer on
the same frame, plus how far those networks are from each other.

Why (docs/experiments.md, "What could foresee the failures"): a frame-novelty score (autoencoder, shift) saw
nothing of ``generalist.onnx``'s failures; what foresaw them was steering against steering. A degraded served
model is seen only against another network (its distance to a sound network: 80 % recall at 1 s), and hard
geometry where networks disagree (the stand-in ensemble's spread: AUC 0.87 on nominal driving and with the spawn
turned). Members trained to the served model's recipe with other seeds (``rbc train --recipe R --seed N``) differ
where the training data is thin, which noised copies of one network only imitate.

The score of a frame, with ``s`` the served network's own output (fed by the server: the graph's second input,
before the serving gain, the clamping and the smoothing) and ``m_1..m_k`` the members' outputs::

    |s - mean(m)| + std(m)        (std over the k members, population: divided by k)

Why both terms, added: each covers one of the two failure families above and neither is zero when the other is
(a degraded served model far from members that agree; members that part on a frame where the served one sits
between them), and both are steering differences in the same unit, so their sum needs no weight fitted on
failures (the calibration sets one threshold on nominal driving only). ``spread=False`` leaves the first term,
for comparing the two.

The served network is not in the graph: the server already ran it, so the monitor costs one run per member.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from drive_server.serving.settings import SERVING_KEY, Serving
from models.onnxfiles.ensemble_onnx import EnsembleError, check_members, member_nodes
from models.onnxfiles.onnx_metadata import read_steering_graph
from protocol.errors import BadValue

SCORE_NAME = "ensemble"
#: The fewest members: with one there is no spread, and one other network is a comparison, not an ensemble.
MIN_MEMBERS = 2
#: Largest |graph - numpy| on the random frames the graph is checked on before it is kept.
TOLERANCE = 1e-4
#: The graph's second input: the served network's steering, (batch, 1).
STEERING_INPUT = "served_steering"


def _digest(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def check_ensemble_members(served: Path, members: Sequence[Path]) -> list[dict[str, str]]:
    """The members' record (file, sha256) if they can watch ``served``; BadValue (one line) if there are fewer than
    two, one is the served model itself or another member, or one reads another input than the served model
    (preprocessing contract, input shape), runs another ONNX opset, is served with another steering gain (its
    output would be in another unit) or differs in answering the mirror average (rbc mirror)."""
    if len(members) < MIN_MEMBERS:
        raise BadValue(f"the ensemble score needs at least {MIN_MEMBERS} members (--member), got {len(members)}",
                       "train the served model's recipe with other seeds: rbc train --recipe R --seed N")
    seen = {_digest(served): f"the served model {Path(served).name}"}
    record = []
    for path in members:
        digest = _digest(path)
        if digest in seen:
            raise BadValue(f"member {path}: the same file as {seen[digest]}; members are other networks")
        seen[digest] = f"member {Path(path).name}"
        record.append({"file": Path(path).name, "sha256": digest})
    graphs = [read_steering_graph(p, BadValue) for p in (served, *members)]
    try:
        check_members([served, *members], graphs)
    except EnsembleError as exc:
        raise BadValue(f"member {exc}", "members must have exactly the served model's preprocessing contract: "
                                        "train them with its recipe (rbc train --recipe R --seed N)") from None
    try:
        gains = [Serving.from_json(g.meta.get(SERVING_KEY)).gain for g in graphs]
    except ValueError as exc:
        raise BadValue(str(exc).splitlines()[0] if str(exc) else "a member's serving settings are unusable") from None
    mirrored = [bool(g.info.get("mirror_average")) for g in graphs]
    for path, gain, mirror in zip(members, gains[1:], mirrored[1:], strict=True):
        if gain != gains[0]:
            raise BadValue(f"member {path}: served with steering gain {gain:g}, {Path(served).name} with "
                           f"{gains[0]:g}; members must be served alike")
        if mirror != mirrored[0]:
            raise BadValue(f"member {path}: {'answers' if mirror else 'does not answer'} the mirror average and "
                           f"{Path(served).name} {'does not' if mirror else 'does'}; members must be made alike",
                           "give every member the served model's treatment (rbc mirror)")
    return record


def ensemble_score_graph(served: Path, members: Sequence[Path], spread: bool = True, seed: int = 0) -> bytes:
    """ONNX bytes: (the served model's preprocessed frame, its network's steering (batch, 1)) -> the score per frame
    (module docstring), checked against the members run one by one on random frames (``seed``)."""
    import onnx
    from onnx import TensorProto, helper

    check_ensemble_members(served, members)
    first = read_steering_graph(served, BadValue)
    graphs = [read_steering_graph(p, BadValue) for p in members]
    image = next(i for i in first.proto.graph.input if i.name == first.input_name)
    nodes, initializers, outputs = member_nodes(graphs, first.input_name)
    initializers.append(helper.make_tensor("ens_flat", TensorProto.INT64, [1], [-1]))
    flat = [f"ens_m{k}" for k in range(len(outputs))]
    nodes += [helper.make_node("Reshape", [o, "ens_flat"], [f]) for o, f in zip(outputs, flat, strict=True)]
    nodes += [helper.make_node("Reshape", [STEERING_INPUT, "ens_flat"], ["ens_served"]),
              helper.make_node("Mean", flat, ["ens_mean"]),
              helper.make_node("Sub", ["ens_served", "ens_mean"], ["ens_diff"]),
              helper.make_node("Abs", ["ens_diff"], ["ens_gap" if spread else "score"])]
    if spread:
        for f in flat:
            nodes += [helper.make_node("Sub", [f, "ens_mean"], [f"{f}_dev"]),
                      helper.make_node("Mul", [f"{f}_dev", f"{f}_dev"], [f"{f}_sq"])]
        nodes += [helper.make_node("Mean", [f"{f}_sq" for f in flat], ["ens_var"]),
                  helper.make_node("Sqrt", ["ens_var"], ["ens_std"]),
                  helper.make_node("Add", ["ens_gap", "ens_std"], ["score"])]
    steering = helper.make_tensor_value_info(STEERING_INPUT, TensorProto.FLOAT, ["batch", 1])
    score = helper.make_tensor_value_info("score", TensorProto.FLOAT, ["batch"])
    graph = helper.make_graph(nodes, "rbc_ensemble_disagreement", [image, steering], [score], initializers)
    model = helper.make_model(graph, opset_imports=list(graphs[0].proto.opset_import),
                              ir_version=graphs[0].proto.ir_version)
    onnx.checker.check_model(model)
    out = model.SerializeToString()
    _verify(out, list(members), first.contract.input_shape[1:], spread, seed)
    return out


def ensemble_scores(served: np.ndarray, members: np.ndarray, spread: bool = True) -> np.ndarray:
    """The score in numpy: ``served`` (N,) and ``members`` (k, N) steering -> (N,) (what the graph computes)."""
    members = np.asarray(members, np.float64)
    gap = np.abs(np.asarray(served, np.float64) - members.mean(axis=0))
    return gap + members.std(axis=0) if spread else gap


def network_outputs(model: Path, frames: np.ndarray, batch_size: int = 256) -> np.ndarray:
    """A steering model's own output (before gain, clamping and smoothing) on preprocessed frames, (N,) float32:
    the served steering a monitor is calibrated with. Frame by frame where the model's batch is fixed."""
    import onnxruntime as ort

    session = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])
    inp = session.get_inputs()[0]
    step = batch_size if not isinstance(inp.shape[0], int) else 1
    out = [np.asarray(session.run(None, {inp.name: np.ascontiguousarray(frames[i:i + step], np.float32)})[0])
           .reshape(-1) for i in range(0, len(frames), step)]
    return np.concatenate(out).astype(np.float32) if out else np.zeros(0, np.float32)


def _verify(graph: bytes, members: list[Path], shape: tuple[int, ...], spread: bool, seed: int) -> None:
    """The graph against the members run one by one and the score in numpy; BadValue beyond ``TOLERANCE``."""
    import onnxruntime as ort

    rng = np.random.default_rng(seed)
    frames = (rng.random((3, *shape), dtype=np.float32) - 0.5).astype(np.float32)
    served = rng.uniform(-1, 1, len(frames)).astype(np.float32)
    want = ensemble_scores(served, np.stack([network_outputs(m, frames) for m in members]), spread)
    session = ort.InferenceSession(graph, providers=["CPUExecutionProvider"])
    frame_name, steering_name = (i.name for i in session.get_inputs())
    got = np.asarray(session.run(None, {frame_name: frames, steering_name: served[:, None]})[0]).reshape(-1)
    worst = float(np.abs(got - want).max())
    if not np.isfinite(worst) or worst >= TOLERANCE:
        raise BadValue(f"the ensemble monitor's graph differs from its members by {worst:.3g} on random frames")
