"""Which score could foresee the failures: an offline study on runs already driven (``rbc monitor failures``), to
choose the next monitor before building it.

Every candidate is scored per frame on the steering model's own recorded inputs and aggregated over the
monitor's one-second window (the mean, or for the steering's spread its standard deviation over the window). A
window is labelled by the failure predictor's rules (:func:`models.monitoring.failures.labels`: positive up to
3 s before an off-road, cone or spin-out take-over, negative with none within 6 s). Per score and axis: the ROC
AUC of positive against negative windows, and the benchmark's recall at 1, 2 and 3 s (the one-second slice,
:mod:`tools.monitoreval.scoring`) at a threshold at the 99th percentile of the calibration laps' windows (their
stretches away from take-overs, as ``rbc monitor fit`` calibrates).

The candidates: (a) the score of the monitor the reference file carries (when the study was run: the autoencoder)
and the served model's shift disagreement; (b) the steering itself (its size, its spread over a second, its change
from frame to frame), of the reference model and of the served one; (c) for a run driven by a weight-noised copy
(:func:`tools.monitoreval.modelfiles.degraded_model`, recreated from the run's sigma and seed), the served
steering's distance to the reference model, to the reference's network without its mirror average, and to every
other model file of the same input contract; (d) an ensemble's spread: of the same-contract models if there are any,
of the served model's two mirrored halves, and of the served model beside copies of it with a little weight noise. A
calibration lap's served model is the reference.

    python -m tools.monitoreval.study --failures DIR --calibration DIR --json OUT

ONNX Runtime, numpy and the ``onnx`` package (graph edits); no torch.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drive_server.serving.monitor import FRAMES_PER_SECOND
from models.monitoring.failures import LabelRules, labels, load_run, run_files
from protocol.errors import BadValue, UserError
from tools.monitoreval.candidates import Study, slice_answers, window_scores
from tools.monitoreval.scoring import DEFAULT_RULES, RunTrace, ScoringRules, score

DEFAULT_MODEL = Path(__file__).resolve().parents[2] / "models" / "pretrained" / "generalist.onnx"
#: The axes of ``rbc monitor failures``' runs, in the table's order; "all" pools them.
AXES = ("none", "light", "yaw", "cones", "weight_noise")
#: A calibration lap's stretches away from take-overs (``rbc monitor fit``'s own rule, models.monitoring.fit).
BEFORE_TAKEOVER_S, AFTER_TAKEOVER_S = 10.0, 4.0


def uneventful(t: np.ndarray, takeovers: Sequence[tuple[float, str]]) -> list[tuple[int, int]]:
    """A calibration lap's stretches (frame spans) away from its take-overs: ``rbc monitor fit``'s rule."""
    keep = np.ones(len(t), bool)
    for when, _ in takeovers:
        keep &= ~((t > when - BEFORE_TAKEOVER_S) & (t < when + AFTER_TAKEOVER_S))
    edges = np.flatnonzero(np.diff(np.r_[0, keep.astype(np.int8), 0]))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True) if b > a]


@dataclass
class ScoredRun:
    """One failure run's one-second scores per frame, with what the benchmark's rules need."""

    name: str
    axis: str
    group: str
    t: np.ndarray
    takeovers: list[tuple[float, str]]
    sim_time_s: float
    scores: dict[str, np.ndarray] = field(default_factory=dict)


def roc_auc(positive: np.ndarray, negative: np.ndarray) -> float | None:
    """The probability that a positive scores above a negative (ties count half); None without both kinds."""
    pos, neg = np.asarray(positive, np.float64), np.asarray(negative, np.float64)
    if pos.size == 0 or neg.size == 0:
        return None
    both = np.concatenate([pos, neg])
    order = np.argsort(both, kind="mergesort")
    ranks = np.empty(both.size, np.float64)
    sorted_ = both[order]
    bounds = np.flatnonzero(np.r_[True, sorted_[1:] != sorted_[:-1], True])
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):  # tied values share their mean rank
        ranks[order[a:b]] = (a + b + 1) / 2.0
    return float((ranks[:pos.size].sum() - pos.size * (pos.size + 1) / 2.0) / (pos.size * neg.size))


def evaluate(runs: Sequence[ScoredRun], calibration: dict[str, np.ndarray], keys: Sequence[str],
             quantile: float = 0.99, rules: ScoringRules = DEFAULT_RULES,
             label_rules: LabelRules | None = None) -> dict[str, dict[str, Any]]:
    """Per score: the threshold (``quantile`` of the calibration windows) and, per axis and for all runs, the AUC,
    the recall at 1/2/3 s, the misbehaviours and the share of negative windows above the threshold."""
    out: dict[str, dict[str, Any]] = {}
    labelled = {r.name: labels(r.t, r.takeovers, label_rules or LabelRules()) for r in runs}
    for key in keys:
        threshold = float(np.quantile(calibration[key], quantile))
        axes: dict[str, Any] = {}
        for axis in (*AXES, "all"):
            subset = [r for r in runs if axis in ("all", r.axis)]
            if not subset:
                continue
            pos = np.concatenate([r.scores[key][labelled[r.name] == 1] for r in subset])
            neg = np.concatenate([r.scores[key][labelled[r.name] == 0] for r in subset])
            traces = [RunTrace(r.name, r.group, r.t, (r.scores[key] > threshold).astype(np.int8), r.takeovers,
                               r.sim_time_s) for r in subset]
            figures = score(traces, rules)
            auc = roc_auc(pos, neg)
            axes[axis] = {"auc": None if auc is None else round(auc, 4), "positive_windows": int(pos.size),
                          "negative_windows": int(neg.size), "misbehaviours": figures.misbehaviours,
                          "undetectable": {k: figures.undetectable[k] for k in ("1", "2", "3")},
                          "recall_at": {k: round(figures.recall_at[k], 4) for k in ("1", "2", "3")},
                          "alarmed_negatives": round(float(np.mean(neg > threshold)), 4) if neg.size else None}
        out[key] = {"threshold": threshold, "threshold_is_zero": threshold == 0.0, "axes": axes}
    return out


def score_failures(study: Study, files: Sequence[Path], window: int) -> list[ScoredRun]:
    out = []
    cache = files[0].parent / "models" if files else None
    for k, path in enumerate(files):
        start = time.perf_counter()
        run = load_run(path)
        answers = study.frame_answers(run, cache)
        out.append(ScoredRun(run.name, str(run.meta.get("axis", "none")), str(run.meta.get("group", "")),
                             np.asarray(run.t, np.float64), list(run.takeovers),
                             float(run.meta.get("sim_time_s", run.t[-1] if len(run.t) else 0.0)),
                             window_scores(answers, window)))
        study.say(f"failure run {k + 1}/{len(files)} {run.name}: {len(run.t):,} frames, "
                  f"{time.perf_counter() - start:.0f} s")
    return out


def score_calibration(study: Study, files: Sequence[Path], window: int) -> tuple[dict[str, np.ndarray], int]:
    """Every candidate's windows over the calibration laps' stretches away from take-overs; and the frame count."""
    parts: dict[str, list[np.ndarray]] = {}
    frames = 0
    for k, path in enumerate(files):
        start = time.perf_counter()
        run = load_run(path)
        if run.meta.get("weight_noise") or run.meta.get("group", "nominal") != "nominal":
            raise BadValue(f"{path}: a calibration lap is nominal driving of the reference model")
        answers = study.frame_answers(run)
        for a, b in uneventful(np.asarray(run.t, np.float64), run.takeovers):
            frames += b - a
            for key, value in window_scores(slice_answers(answers, a, b), window).items():
                parts.setdefault(key, []).append(value)
        study.say(f"calibration lap {k + 1}/{len(files)} {run.name}: {len(run.t):,} frames, "
                  f"{time.perf_counter() - start:.0f} s")
    return {key: np.concatenate(v) for key, v in parts.items()}, frames


def run_study(failures: Path, calibration: Path, study: Study, quantile: float = 0.99,
              window: int = FRAMES_PER_SECOND) -> dict[str, Any]:
    started = time.perf_counter()
    fail_files, cal_files = run_files([failures]), run_files([calibration])
    study.say(f"{len(fail_files)} failure runs, {len(cal_files)} calibration laps; {len(study.keys())} scores")
    runs = score_failures(study, fail_files, window)
    cal, cal_frames = score_calibration(study, cal_files, window)
    keys = study.keys()
    figures = evaluate(runs, cal, keys, quantile)
    return {
        "study": "which score could foresee the failures (tools.monitoreval.study)",
        "model": study.model.name, "model_sha256": study.digest, "window_frames": window, "quantile": quantile,
        "labels": vars(LabelRules()), "scoring": DEFAULT_RULES.to_dict(),
        "data": {"failure_runs": len(runs), "failure_frames": int(sum(len(r.t) for r in runs)),
                 "runs_per_axis": {a: sum(r.axis == a for r in runs) for a in AXES},
                 "calibration_laps": len(cal_files), "calibration_frames": cal_frames},
        "same_contract": study.contracts, "members": study.members, "member_sigma": study.member_sigma,
        "noise_copies": study.copies,
        "scores": {c.key: {"kind": c.kind, "label": c.label, **figures[c.key]} for c in study.candidates()},
        "seconds": round(time.perf_counter() - started, 1)}


def table(result: dict[str, Any]) -> str:
    """The study as a Markdown table: per score, AUC and recall at 1/2/3 s per axis and for all runs (the axis's
    misbehaviours in brackets)."""
    axes = [a for a in (*AXES, "all") if any(a in s["axes"] for s in result["scores"].values())]
    first = next(iter(result["scores"].values()))["axes"]
    head = "| score | " + " | ".join(f"{a.replace('_', ' ')} ({first[a]['misbehaviours']})" for a in axes) + " |"
    lines = [head, "|" + "---|" * (len(axes) + 1)]
    for s in result["scores"].values():
        cells = []
        for axis in axes:
            f = s["axes"].get(axis)
            if f is None:
                cells.append("")
                continue
            auc = "-" if f["auc"] is None else f"{f['auc']:.2f}"
            recall = "/".join(f"{100 * f['recall_at'][k]:.0f}" for k in ("1", "2", "3"))
            cells.append(f"{auc} · {recall}")
        label = s["label"].replace("|", "\\|")
        lines.append(f"| {s['kind']}) {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tools.monitoreval.study", description=__doc__.split("\n\n")[0])
    parser.add_argument("--failures", type=Path, required=True, help="folder of rbc monitor failures' runs")
    parser.add_argument("--calibration", type=Path, required=True, help="folder of nominal laps (same format)")
    parser.add_argument("--json", type=Path, required=True, help="where the figures go")
    parser.add_argument("--model", type=Path, default=DEFAULT_MODEL, help="the reference model (it drove the runs)")
    parser.add_argument("--others", type=Path, default=None,
                        help="folder of other model files; those of the reference's input contract are compared "
                             "(default: the reference's folder)")
    parser.add_argument("--members", type=int, default=4, help="weight-perturbed copies in the perturbed ensemble")
    parser.add_argument("--member-sigma", type=float, default=0.1, help="their noise, relative to each tensor's std")
    parser.add_argument("--quantile", type=float, default=0.99, help="of the calibration windows: the threshold")
    parser.add_argument("--threads", type=int, default=1, help="ONNX Runtime threads per graph")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    try:
        if not 0.5 <= args.quantile < 1:
            raise BadValue(f"--quantile must be in [0.5, 1), got {args.quantile:g}")
        study = Study(args.model, args.members, args.member_sigma, args.threads, args.others)
        try:
            result = run_study(args.failures, args.calibration, study, args.quantile)
        finally:
            study.close()
    except UserError as exc:
        print(f"study: error: {exc}", file=sys.stderr)
        return 2
    result["command"] = " ".join(["python -m tools.monitoreval.study", *(sys.argv[1:] if argv is None else argv)])
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    print("AUC · recall % at 1/2/3 s, threshold at the calibration windows' "
          f"{100 * args.quantile:g}th percentile")
    print(table(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
