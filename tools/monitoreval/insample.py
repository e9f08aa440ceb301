"""The anchors' own protocol, reproduced on our drives: each monitor's threshold fitted IN-SAMPLE, on the very
nominal driving its false positives are then counted on, as SelfOracle, ThirdEye and the ICST 2024 uncertainty
study do; a like-for-like row beside their published figures.

Their threshold: a gamma distribution fitted to the nominal one-second windows' scores, its 95 % quantile. SciPy is
not a dependency of the project, so the fit is written here in closed form: the shape by Minka's approximation of
the maximum-likelihood estimate (within 1.5 % of it; "Estimating a Gamma distribution", 2002), the quantile by the
Wilson-Hilferty cube-root normal approximation. A frame is predicted when its one-second window mean is at or above
the threshold (no hand-back delay: the anchors compare each window with the threshold), and the slices and nominal
windows are :func:`tools.monitoreval.scoring.score`'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TypedDict, cast

import numpy as np

from tools.monitoreval.report import pct, trace
from tools.monitoreval.runset import RunSpec
from tools.monitoreval.scoring import RunTrace, ScoringRules, nominal_stretches, score

#: The standard normal's 95 % quantile: the anchors' confidence (SelfOracle's and ThirdEye's gamma quantile).
_Z95 = 1.6448536269514722


def gamma_quantile_95(values: np.ndarray) -> float:
    """The 95 % quantile of a gamma distribution fitted to positive ``values`` (location 0, as the anchors fit)."""
    x = np.asarray(values, dtype=np.float64)
    x = x[np.isfinite(x)]
    if x.size < 2:
        raise ValueError("a gamma fit needs at least 2 finite values")
    x = np.maximum(x, 1e-3 * float(x[x > 0].min()) if np.any(x > 0) else 1e-15)  # the log needs x > 0
    mean = float(x.mean())
    s = math.log(mean) - float(np.log(x).mean())
    if s <= 1e-12:  # all equal: no spread to fit
        return mean
    shape = (3.0 - s + math.sqrt((s - 3.0) ** 2 + 24.0 * s)) / (12.0 * s)
    scale = mean / shape
    h = 1.0 / (9.0 * shape)
    return shape * scale * max(0.0, 1.0 - h + _Z95 * math.sqrt(h)) ** 3


def window_means(values: Sequence[float], window: int) -> np.ndarray:
    """Each frame's mean over the last ``window`` frames (fewer at the start), as the server's monitor averages."""
    v = np.asarray(values, dtype=np.float64)
    c = np.concatenate([[0.0], np.cumsum(v)])
    i = np.arange(1, v.size + 1)
    lo = np.maximum(0, i - window)
    return (c[i] - c[lo]) / (i - lo)


def _nominal_frames(run: RunTrace, rules: ScoringRules) -> np.ndarray:
    """The frames of a nominal run that the false-positive windows cover (:func:`nominal_stretches`)."""
    keep = np.zeros(run.t.size, dtype=bool)
    for start, end in nominal_stretches(run, rules):
        keep |= (run.t >= start) & (run.t < end)
    return keep


class InSampleRow(TypedDict):
    """A monitor's row of the anchors' protocol: the table's cells and the figures behind them."""

    monitor: str
    threshold: str
    r1: str
    r2: str
    r3: str
    r46: str
    p13: str
    f3: str
    nominal_alarmed: str
    figures: dict[str, object]


def _scores(run: Mapping[str, object], name: str | None, window: int) -> np.ndarray:
    """A run's one-second window means: the driving monitor's as stored, a shadow's from its per-frame scores."""
    if name is None:
        return np.asarray([m if m is not None else 0.0 for m in cast(Sequence[float | None], run["mean"])],
                          dtype=np.float64)
    return window_means(cast(Mapping[str, Sequence[float]], run["shadows"])[name], window)


def in_sample(results: Sequence[tuple[RunSpec, str, Mapping[str, object]]], rules: ScoringRules,
              monitors: dict[str | None, tuple[str, int]]) -> list[InSampleRow]:
    """One row per monitor, scored by the anchors' protocol on the ``warn`` drives. ``monitors``: shadow name
    (None: the driving monitor, whose stored one-second means are used) -> (label, its window in frames)."""
    warn = [(s, r) for s, m, r in results if m == "warn"]
    traces = [trace(s, dict(r)) for s, r in warn]
    masks = [_nominal_frames(t, rules) if t.group == "nominal" else None for t in traces]
    rows: list[InSampleRow] = []
    for name, (label, window) in monitors.items():
        means = [_scores(r, name, window) for _, r in warn]
        nominal = [m[k] for k, m in zip(masks, means, strict=True) if k is not None]
        if not nominal or sum(v.size for v in nominal) < 2:
            continue
        threshold = gamma_quantile_95(np.concatenate(nominal))
        replays = [RunTrace(t.name, t.group, t.t, (m >= threshold).astype(np.uint8), t.takeovers, t.sim_time_s,
                            t.meta) for t, m in zip(traces, means, strict=True)]
        f = score(replays, rules)
        rows.append({"monitor": f"ours: {label}, the anchors' protocol (threshold in-sample)",
                     "threshold": f"{threshold:.4g}",
                     "r1": pct(f.recall_at["1"]), "r2": pct(f.recall_at["2"]), "r3": pct(f.recall_at["3"]),
                     "r46": pct(f.recall_4_6), "p13": pct(f.precision_1_3), "f3": f"{f.f3_1_3:.2f}",
                     "nominal_alarmed": pct(f.false_windows / f.nominal_windows if f.nominal_windows else None),
                     "figures": f.to_dict()})
    return rows


def markdown(record: Mapping[str, object]) -> str:
    """The in-sample rows as a table of the benchmark's ``monitor_eval.md``."""
    rows = cast(list[InSampleRow], record.get("in_sample") or [])
    if not rows:
        return ""
    lines = ["", "### The anchors' protocol: thresholds fitted in-sample on the held-out nominal driving", "",
             "| monitor | threshold | recall 1 / 2 / 3 s | recall 4-6 s | precision 1-3 s | F3 1-3 s | "
             "nominal windows alarmed |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['monitor']} | {r['threshold']} | {r['r1']} / {r['r2']} / {r['r3']} | {r['r46']} | {r['p13']} | "
              f"{r['f3']} | {r['nominal_alarmed']} |" for r in rows]
    return "\n".join(lines) + "\n"
