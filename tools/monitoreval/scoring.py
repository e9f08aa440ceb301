"""How a monitor is scored: the rules as data, the figures as small records (the CARLA leaderboard's way).

A misbehaviour is the first frame of a referee take-over for leaving the road, a cone or a spin-out (stuck and
wrong-way are counted apart), in any run, nominal ones included; one within ``settle_s`` of the run's start or of
the previous take-over is not a failure of its own and is left out, and one with less history than a slice needs
is counted as undetectable (a miss), never dropped.

Two protocols. The anchors' (SelfOracle, ThirdEye, the ICST 2024 uncertainty study): a misbehaviour is
detected "at k s" if the monitor is in warning or alarm at some frame of the one-second slice [T-k-1, T-k);
false positives are the one-second windows of held-out nominal driving with a warning in them (none of the 10 s
before a take-over: a warning there foresaw a real failure). Ours, for
deployment: debounced episodes (the server's own state machine), the lead of the first episode before each
misbehaviour, and false alarm episodes per hour of held-out nominal driving with a 95 % upper bound.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

#: Take-over causes that are misbehaviours; stuck and wrong-way are counted apart.
MISBEHAVIOUR_CAUSES = ("off_road", "cone", "spin_out")


@dataclass(frozen=True)
class ScoringRules:
    settle_s: float = 4.0  # after the start and after each take-over: no misbehaviour, no nominal window
    horizon_s: float = 10.0  # an episode starting this long before a misbehaviour or less predicts it
    slices_s: tuple[int, ...] = (1, 2, 3, 4, 5, 6)  # the anchors' one-second slices
    level: int = 1  # the state counted as a prediction: 1 warning or alarm, 2 alarm only
    beta: float = 3.0  # F-beta: recall weighed beta times precision (ThirdEye's F3)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


#: The rules every benchmark uses unless told otherwise.
DEFAULT_RULES = ScoringRules()


@dataclass
class RunTrace:
    """One monitored run: per-frame time (simulated s) and state, and its take-overs (time, cause)."""

    name: str
    group: str  # "nominal", "perturbed" or "degraded"
    t: np.ndarray
    level: np.ndarray
    takeovers: list[tuple[float, str]]
    sim_time_s: float
    meta: dict[str, Any] = field(default_factory=dict)


def _settled(run: RunTrace, rules: ScoringRules) -> list[tuple[float, str, float]]:
    """(time, cause, history start) of each take-over after a settled stretch: the history starts at the previous
    take-over (or the start) plus ``settle_s``."""
    out, last = [], 0.0
    for when, cause in run.takeovers:
        out.append((when, cause, last + rules.settle_s))
        last = when
    return out


def misbehaviours(run: RunTrace, rules: ScoringRules) -> list[tuple[float, str, float]]:
    return [m for m in _settled(run, rules) if m[1] in MISBEHAVIOUR_CAUSES and m[0] >= m[2]]


def episodes(run: RunTrace, rules: ScoringRules) -> np.ndarray:
    """Start times of the debounced prediction episodes (entries into the counted state)."""
    on = run.level >= rules.level
    starts = np.flatnonzero(on & ~np.concatenate([[False], on[:-1]]))
    return run.t[starts]


def first_warning_leads(run: RunTrace, rules: ScoringRules) -> list[tuple[float, str, float | None]]:
    """(time, cause, lead) of each misbehaviour: how long before it the first prediction episode within the
    horizon began (the whole horizon for one in force since earlier still), None if none."""
    out: list[tuple[float, str, float | None]] = []
    starts = episodes(run, rules)
    for when, cause, history in misbehaviours(run, rules):
        before = starts[(starts > when - rules.horizon_s) & (starts <= when) & (starts >= history - rules.settle_s)]
        window = (run.t >= max(history, when - rules.horizon_s)) & (run.t < when)
        if before.size:
            out.append((when, cause, when - float(before[0])))
        elif np.any(run.level[window] >= rules.level):
            out.append((when, cause, rules.horizon_s))
        else:
            out.append((when, cause, None))
    return out


#: A take-over is foreseen "in time" when the first warning came at least this long before it (drive-log, eval).
IN_TIME_S = 1.0


def foresight(run: RunTrace, rules: ScoringRules) -> dict[str, Any]:
    """Which of a run's misbehaviours the monitor foresaw, and how early (:func:`first_warning_leads`): the counts
    and leads that ``rbc drive-log`` and ``rbc eval --monitor`` record for a run."""
    leads = [lead for *_, lead in first_warning_leads(run, rules)]
    return {"takeovers_scored": len(leads), "foreseen": sum(x is not None for x in leads),
            "foreseen_1s": sum(x is not None and x >= IN_TIME_S for x in leads),
            "leads_s": [None if x is None else round(x, 2) for x in leads]}


def _slice_hit(run: RunTrace, when: float, k: int, history: float, rules: ScoringRules) -> bool | None:
    lo, hi = when - k - 1, when - k
    if lo < history:
        return None  # too little history: undetectable at this slice
    inside = (run.t >= lo) & (run.t < hi)
    return bool(np.any(run.level[inside] >= rules.level))


def nominal_stretches(run: RunTrace, rules: ScoringRules) -> list[tuple[float, float]]:
    """(start, end) of the stretches of a nominal run that count as nominal driving: ``settle_s`` after the start
    and after each take-over, and none of the ``horizon_s`` before a take-over (a warning there foresaw a real
    failure: not a false alarm)."""
    bounds = [0.0, *[w for w, _ in run.takeovers], run.sim_time_s]
    return [(a + rules.settle_s, b - rules.horizon_s if k < len(run.takeovers) else b)
            for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True))]


def nominal_windows(run: RunTrace, rules: ScoringRules) -> tuple[int, int]:
    """(one-second windows, windows with a prediction) of a nominal run, over its :func:`nominal_stretches`."""
    total = hit = 0
    for start, end in nominal_stretches(run, rules):
        for lo in np.arange(start, end - 1.0 + 1e-9, 1.0):
            inside = (run.t >= lo) & (run.t < lo + 1.0)
            total += 1
            hit += bool(np.any(run.level[inside] >= rules.level))
    return total, hit


def poisson_upper(count: int, confidence: float = 0.95) -> float:
    """The exact one-sided upper confidence bound of a Poisson mean after observing ``count`` events."""
    def cdf(mu: float) -> float:  # P(X <= count)
        term = total = math.exp(-mu)
        for i in range(1, count + 1):
            term *= mu / i
            total += term
        return total
    lo, hi = 0.0, max(10.0, 10.0 * (count + 1))
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if cdf(mid) > 1 - confidence else (lo, mid)
    return hi


def f_beta(precision: float, recall: float, beta: float) -> float:
    if precision + recall == 0:
        return 0.0
    return (1 + beta**2) * precision * recall / (beta**2 * precision + recall)


@dataclass
class Figures:
    """The benchmark's figures for one monitor (all fractions 0..1, times in s)."""

    misbehaviours: int
    undetectable: dict[str, int]
    other_takeovers: dict[str, int]
    recall_at: dict[str, float]  # slice k (anchors' protocol)
    recall_4_6: float
    nominal_windows: int
    false_windows: int
    precision_at: dict[str, float]
    f1_at: dict[str, float]
    f3_at: dict[str, float]
    f3_1_3: float
    precision_1_3: float
    recall_1_3: float
    episodes: int
    lead_recall_at: dict[str, float]  # a first episode at least k s ahead (deployment)
    lead_precision: float  # episodes followed by a misbehaviour within the horizon, of all episodes
    lead_median_s: float | None
    lead_p10_s: float | None
    nominal_hours: float
    false_episodes: int
    false_per_hour: float
    false_per_hour_upper95: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def score(runs: Sequence[RunTrace], rules: ScoringRules = DEFAULT_RULES) -> Figures:
    nominal = [r for r in runs if r.group == "nominal"]
    found = [(r, m) for r in runs for m in misbehaviours(r, rules)]  # a nominal run's failure is a failure too
    others: dict[str, int] = {}
    for r in runs:
        for _, cause in r.takeovers:
            if cause not in MISBEHAVIOUR_CAUSES:
                others[cause] = others.get(cause, 0) + 1
    n = len(found)
    hits = {k: [_slice_hit(r, when, k, hist, rules) for r, (when, _, hist) in found] for k in rules.slices_s}
    undetectable = {str(k): sum(h is None for h in v) for k, v in hits.items()}
    recall = {str(k): (sum(bool(h) for h in v) / n if n else 0.0) for k, v in hits.items()}
    early = [any(bool(hits[k][i]) for k in (4, 5, 6) if k in hits) for i in range(n)]
    within = [any(bool(hits[k][i]) for k in (1, 2, 3) if k in hits) for i in range(n)]
    windows = [nominal_windows(r, rules) for r in nominal]
    total_w, false_w = sum(w for w, _ in windows), sum(h for _, h in windows)

    def precision(tp: int) -> float:
        return tp / (tp + false_w) if tp + false_w else 0.0

    prec = {str(k): precision(sum(bool(h) for h in hits[k])) for k in rules.slices_s}
    f1 = {k: f_beta(prec[k], recall[k], 1.0) for k in prec}
    f3 = {k: f_beta(prec[k], recall[k], rules.beta) for k in prec}
    tp13 = sum(within)
    p13, r13 = precision(tp13), (tp13 / n if n else 0.0)
    # deployment: leads of the first episode within the horizon before each misbehaviour
    leads = [lead for r in runs for *_, lead in first_warning_leads(r, rules)]
    lead_recall = {str(k): (sum(1 for x in leads if x is not None and x >= k) / n if n else 0.0) for k in (1, 2, 3)}
    got = np.array([x for x in leads if x is not None])
    all_eps, useful = 0, 0
    for r in runs:
        starts = episodes(r, rules)
        all_eps += len(starts)
        fails = np.array([m[0] for m in misbehaviours(r, rules)])
        useful += sum(bool(np.any((fails >= s) & (fails - s <= rules.horizon_s))) for s in starts)
    hours = sum(r.sim_time_s for r in nominal) / 3600.0
    false_eps = 0  # nominal episodes that foresaw no failure
    for r in nominal:
        fails = np.array([m[0] for m in misbehaviours(r, rules)])
        false_eps += sum(not np.any((fails >= s) & (fails - s <= rules.horizon_s)) for s in episodes(r, rules))
    return Figures(
        misbehaviours=n, undetectable=undetectable, other_takeovers=others, recall_at=recall,
        recall_4_6=(sum(early) / n if n else 0.0), nominal_windows=total_w, false_windows=false_w,
        precision_at=prec, f1_at=f1, f3_at=f3, f3_1_3=f_beta(p13, r13, rules.beta), precision_1_3=p13,
        recall_1_3=r13, episodes=all_eps, lead_recall_at=lead_recall,
        lead_precision=(useful / all_eps if all_eps else 0.0),
        lead_median_s=float(np.median(got)) if got.size else None,
        lead_p10_s=float(np.percentile(got, 10)) if got.size else None,
        nominal_hours=hours, false_episodes=false_eps,
        false_per_hour=(false_eps / hours if hours else math.nan),
        false_per_hour_upper95=(poisson_upper(false_eps) / hours if hours else math.nan))
