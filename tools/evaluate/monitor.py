"""``rbc eval --monitor warn|act``: the model's misbehaviour monitor on every run, as ``rbc sim --monitor`` drives it.

Per run (:func:`run_monitor`, in the worker that drove it): the monitor's warning and alarm episodes (the server's
own state machine), the simulated seconds spent in each state, and which take-overs it foresaw and how early
(:func:`tools.monitoreval.scoring.foresight`, the rules of ``rbc drive-log`` and the benchmark). Per experiment row
(:func:`summarize_monitor`): the same summed over the row's runs; :func:`monitor_cells` writes them as the printed
table's columns.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from tools.monitoreval.scoring import DEFAULT_RULES, IN_TIME_S, ScoringRules, foresight
from tools.monitoreval.summary import run_trace

if TYPE_CHECKING:
    from drive_server.serving.client_monitor import MonitorPolicy
    from drive_server.serving.monitor import MonitorSpec
    from tools.evaluate.evalrecord import EvalRun
    from tools.sim.driving.drivers import OnnxDriver
    from tools.sim.driving.scenario import RunResult

STATES = ("warning", "alarm")  # drive_server.serving.client_monitor.Level 1 and 2, by their labels


def monitor_meta(spec: MonitorSpec, policy: MonitorPolicy, rules: ScoringRules = DEFAULT_RULES) -> dict[str, Any]:
    """What results.json says of the monitor an evaluation drove with: its score, thresholds, mode and rules."""
    meta: dict[str, Any] = {"mode": policy.mode.value, "score": spec.score, "warn": spec.warn, "alarm": spec.alarm,
                            "window_frames": spec.window, "release_frames": policy.release_frames,
                            "foreseen_at_least_s": IN_TIME_S, "rules": rules.to_dict()}
    if policy.mode == "act":
        meta["slow_factor"] = policy.slow_factor
    return meta


def run_monitor(driver: OnnxDriver, result: RunResult, rules: ScoringRules = DEFAULT_RULES) -> dict[str, Any]:
    """One run's monitor: episodes and simulated seconds in warning and alarm, take-overs foreseen and their leads."""
    monitor = driver.monitor
    assert monitor is not None, "a monitored run"
    trace = run_trace(driver, result)
    # each frame's state holds until the next frame (the last one until the run's end): seconds, not frames, so a
    # real-time run's uneven frames weigh as long as they lasted
    end = max(result.sim_time_s, float(trace.t[-1])) if trace.t.size else result.sim_time_s
    held = np.diff(trace.t, append=end) if trace.t.size else np.zeros(0)
    record: dict[str, Any] = {
        "episodes": {state: int(monitor.state.episodes[state]) for state in STATES},
        "time_s": {state: round(float(held[trace.level == level].sum()), 3)
                   for level, state in enumerate(STATES, start=1)},
        "scored_s": round(float(held.sum()), 3), "frames_scored": int(trace.t.size)}
    record |= foresight(trace, rules)
    leads = [x for x in record["leads_s"] if x is not None]
    record["lead_median_s"] = round(statistics.median(leads), 2) if leads else None
    if monitor.failed:
        record["failed"] = monitor.failed
    return record


def summarize_monitor(records: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
    """One experiment row: its runs' monitor figures summed (shares of the scored time; the median of all leads)."""
    runs = [r["monitor"] for r in records if r.get("monitor")]
    scored = sum(m["scored_s"] for m in runs)
    leads = [x for m in runs for x in m["leads_s"] if x is not None]
    return {"runs": len(runs),
            "episodes": {state: sum(m["episodes"][state] for m in runs) for state in STATES},
            "time_share": {state: (sum(m["time_s"][state] for m in runs) / scored if scored else 0.0)
                           for state in STATES},
            "takeovers_scored": sum(m["takeovers_scored"] for m in runs),
            "foreseen": sum(m["foreseen"] for m in runs), "foreseen_1s": sum(m["foreseen_1s"] for m in runs),
            "lead_median_s": round(statistics.median(leads), 2) if leads else None,
            "failed": sum(1 for m in runs if m.get("failed"))}


def add_monitor_rows(summary: dict[str, Any], records: Sequence[EvalRun]) -> None:
    """Give every experiment row of ``summary`` its runs' monitor figures (``summary[key]["monitor"]``)."""
    for key, entry in summary.items():
        entry["monitor"] = summarize_monitor(r for r in records if r["experiment"] == key)


#: The printed table's monitor columns (:func:`monitor_cells`), and what they say.
MONITOR_HEADS = ("warn/alarm", "% warn/alarm", f"foreseen ≥{IN_TIME_S:g} s", "median lead")
MONITOR_LEGEND = (
    "warn/alarm: episodes; % warn/alarm: share of the simulated time; foreseen: take-overs (off the road,\n"
    f"a cone, a spin-out) with a warning at least {IN_TIME_S:g} s before; median lead: of the first warnings")


def monitor_cells(row: Mapping[str, Any] | None) -> tuple[str, ...]:
    """The printed table's monitor columns for one experiment row (dashes for a row without monitored runs)."""
    if not row or not row.get("runs"):
        return ("-",) * len(MONITOR_HEADS)
    eps, share = row["episodes"], row["time_share"]
    lead = row["lead_median_s"]
    return (f"{eps['warning']} / {eps['alarm']}",
            f"{100 * share['warning']:.1f} / {100 * share['alarm']:.1f}",
            f"{row['foreseen_1s']} of {row['takeovers_scored']}",
            "-" if lead is None else f"{lead:.1f} s")
