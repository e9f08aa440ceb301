"""The benchmark's record and tables: the anchors' protocol beside the published figures, the deployment
figures, the closed loop (``act`` against ``warn``, which drives exactly like ``off``) and the cost."""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from tools.monitoreval.runset import RunSpec
from tools.monitoreval.scoring import MISBEHAVIOUR_CAUSES, RunTrace, ScoringRules, score

if TYPE_CHECKING:
    from drive_server.serving.monitor import MonitorSpec


@dataclass(frozen=True)
class Anchor:
    """A published monitor's figures: recall at the 1, 2, 3 s slices, F3 (None: not reported)."""

    monitor: str
    recall_1: float | None
    recall_2: float | None
    recall_3: float | None
    f3: float | None = None


#: Grewal, Tonella & Stocco, ICST 2024 (arXiv 2404.18573): recall at the 1, 2, 3 s slices; best F3.
ANCHORS = (
    Anchor("deep ensemble, 5 models", 1.00, 1.00, 0.98),
    Anchor("MC-dropout", 0.97, 0.96, 0.93),
    Anchor("SelfOracle (autoencoder)", 0.87, 0.77, 0.66),
    Anchor("ThirdEye (attention)", 0.78, 0.79, 0.71),
    Anchor("best of the study (50-model ensemble)", None, None, None, 0.94),
)


def trace(spec: RunSpec, run: dict[str, Any]) -> RunTrace:
    return RunTrace(spec.name, spec.group, np.asarray(run["t"], dtype=np.float64),
                    np.frombuffer(run["level"].encode(), dtype=np.uint8) - ord("0"),
                    [(float(t), str(c)) for t, c in run["takeovers"]], float(run["sim_time_s"]),
                    {"axis": spec.axis, "intensity": spec.intensity})


def _count(runs: Sequence[dict[str, Any]], causes: Sequence[str]) -> int:
    return sum(1 for r in runs for _, c in r["takeovers"] if c in causes)


def closed_loop(results: Sequence[tuple[RunSpec, str, dict[str, Any]]]) -> dict[str, Any]:
    """``act`` against ``warn`` on the same runs: failures prevented, and the price on nominal driving."""
    by = {(s.name, m): r for s, m, r in results}
    specs = {s.name: s for s, _, _ in results}
    failing = [n for n, s in specs.items() if s.group != "nominal" and (n, "act") in by and (n, "warn") in by]
    nominal = [n for n, s in specs.items() if s.group == "nominal" and (n, "act") in by and (n, "warn") in by]
    if not failing and not nominal:
        return {}
    off_fail = _count([by[(n, "warn")] for n in failing], MISBEHAVIOUR_CAUSES)
    act_fail = _count([by[(n, "act")] for n in failing], MISBEHAVIOUR_CAUSES)
    other = ("stuck", "wrong_way")

    def mean(key: str, mode: str) -> float | None:
        values = [by[(n, mode)][key] for n in nominal if by[(n, mode)][key] is not None]
        return statistics.fmean(values) if values else None

    out = {"failing_runs": len(failing), "misbehaviours_off": off_fail, "misbehaviours_act": act_fail,
           "prevented": (1 - act_fail / off_fail) if off_fail else None,
           "stuck_or_wrong_way_off": _count([by[(n, "warn")] for n in failing], other),
           "stuck_or_wrong_way_act": _count([by[(n, "act")] for n in failing], other),
           "nominal_runs": len(nominal)}
    for key in ("eta", "lap_time_s", "mean_speed_kmh"):
        off, act = mean(key, "warn"), mean(key, "act")
        out[f"nominal_{key}_off"], out[f"nominal_{key}_act"] = off, act
        out[f"nominal_{key}_change"] = (act - off) / off if off and act is not None else None
    return out


def replayed(spec: RunSpec, run: dict[str, Any], values: Sequence[float], monitor: MonitorSpec) -> RunTrace:
    """``run``'s trace had ``monitor`` (its thresholds and window) seen these per-frame ``values``: the values
    through the server's own state machine."""
    from drive_server.serving.client_monitor import MonitorState

    state = MonitorState(monitor)
    levels = np.array([int(state.update(v).level) for v in values], dtype=np.uint8)
    base = trace(spec, run)
    return RunTrace(base.name, base.group, base.t, levels, base.takeovers, base.sim_time_s, base.meta)


def compare(results: Sequence[tuple[RunSpec, str, dict[str, Any]]], rules: ScoringRules,
            shadows: dict[str, MonitorSpec], primary: str,
            labels: dict[str, str] | None = None) -> list[dict[str, Any]]:
    """Every monitor on the same ``warn`` drives, one row each (the driving one first); ``labels``: a shadow's
    name in the table (default: its file's)."""
    warn = [(s, r) for s, m, r in results if m == "warn"]
    out = []
    labels = labels or {}
    for name, traces in [(primary, [trace(s, r) for s, r in warn]),
                         *[(labels.get(n, n), [replayed(s, r, r["shadows"][n], spec) for s, r in warn])
                           for n, spec in shadows.items()]]:
        f = score(traces, rules)
        out.append({"monitor": name, "r1": pct(f.recall_at["1"]), "r2": pct(f.recall_at["2"]),
                    "r3": pct(f.recall_at["3"]), "r46": pct(f.recall_4_6), "f3": f"{f.f3_1_3:.2f}",
                    "lead1": pct(f.lead_recall_at["1"]),
                    "false": f"{f.false_per_hour:.2f} ({f.false_per_hour_upper95:.2f})", "figures": f.to_dict()})
    return out


def _at_threshold(spec: RunSpec, run: dict[str, Any], name: str | None, warn: float, window: int) -> RunTrace:
    """A run's trace had the monitor warned from ``warn`` on (alarms not counted): the driving monitor's stored
    one-second means (a window of 1), or a shadow's stored scores through its window."""
    from drive_server.serving.monitor import MonitorSpec

    if name is None:
        values, spec_window = [m if m is not None else 0.0 for m in run["mean"]], 1
    else:
        values, spec_window = run["shadows"][name], window
    return replayed(spec, run, values, MonitorSpec("sweep", warn, max(warn, 1e30), spec_window))


def sweep(results: Sequence[tuple[RunSpec, str, dict[str, Any]]], rules: ScoringRules,
          monitors: dict[str | None, tuple[str, MonitorSpec]]) -> list[dict[str, Any]]:
    """Each monitor at lower warning thresholds than its calibrated one, on the same drives: what a looser
    false-alarm target would buy. ``monitors``: shadow name (None: the driving one) -> (label, its MonitorSpec).
    The thresholds are the calibration's own 99th percentile, halfway to its maximum, and the calibrated one."""
    warn = [(s, r) for s, m, r in results if m == "warn"]
    out = []
    for name, (label, spec) in monitors.items():
        cal = spec.calibration
        p99, top = cal.get("nominal_p99"), cal.get("nominal_max")
        if p99 is None or top is None:
            continue
        for which, threshold in (("calibration p99", p99), ("halfway to its max", (p99 + top) / 2),
                                 ("calibrated", spec.warn)):
            f = score([_at_threshold(s, r, name, threshold, spec.window) for s, r in warn], rules)
            out.append({"monitor": label, "threshold": f"{threshold:.4g} ({which})",
                        "r123": " / ".join(pct(f.recall_at[k]) for k in ("1", "2", "3")),
                        "lead1": pct(f.lead_recall_at["1"]), "f3": f"{f.f3_1_3:.2f}",
                        "false": f"{f.false_per_hour:.2f} ({f.false_per_hour_upper95:.2f})"})
    return out


def figures(results: Sequence[tuple[RunSpec, str, dict[str, Any]]], rules: ScoringRules) -> dict[str, Any]:
    """The monitor's figures on the ``warn`` runs (which drive exactly as without a monitor)."""
    traces = [trace(s, r) for s, m, r in results if m == "warn"]
    by_axis: dict[str, Any] = {}
    for axis in sorted({t.meta["axis"] for t in traces}):
        f = score([t for t in traces if t.meta["axis"] == axis], rules)  # "none": the nominal runs' own failures
        by_axis[axis] = {"misbehaviours": f.misbehaviours, "recall_1": f.recall_at["1"],
                         "recall_3": f.recall_at["3"], "lead_median_s": f.lead_median_s}
    return {"all": score(traces, rules).to_dict(), "by_axis": by_axis,
            "failed_monitors": sum(1 for _, m, r in results if r.get("monitor_failed"))}


def pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def tables(record: dict[str, Any]) -> str:
    f = record["figures"]["all"]
    lines = ["### Like for like: the anchors' protocol (one-second slices, nominal windows as negatives)", "",
             "| monitor | recall 1 s | recall 2 s | recall 3 s | recall 4-6 s | F3 1-3 s |",
             "|---|---|---|---|---|---|",
             f"| ours: {record['monitor']['score']} | {pct(f['recall_at']['1'])} | {pct(f['recall_at']['2'])} | "
             f"{pct(f['recall_at']['3'])} | {pct(f['recall_4_6'])} | {f['f3_1_3']:.3f} |"]
    for a in ANCHORS:
        lines.append(f"| {a.monitor} (published) | {pct(a.recall_1)} | {pct(a.recall_2)} | {pct(a.recall_3)} | - | "
                     f"{a.f3 if a.f3 is not None else '-'} |")
    lead, p10 = f["lead_median_s"], f["lead_p10_s"]
    lines += ["", f"{f['misbehaviours']} misbehaviours ({f['undetectable']['3']} with too little history for the 3 s "
              f"slice, counted as misses); {f['nominal_windows']:,} nominal one-second windows, "
              f"{f['false_windows']} with a warning.", "",
              "### For deployment: episodes, lead and false alarms", "",
              "| figure | value |", "|---|---|",
              f"| recall with a lead of at least 1 / 2 / 3 s | {pct(f['lead_recall_at']['1'])} / "
              f"{pct(f['lead_recall_at']['2'])} / {pct(f['lead_recall_at']['3'])} |",
              f"| precision of episodes (followed by a misbehaviour within 10 s) | {pct(f['lead_precision'])} |",
              f"| median / p10 lead of the first episode | "
              f"{'-' if lead is None else f'{lead:.1f} s'} / "
              f"{'-' if p10 is None else f'{p10:.1f} s'} |",
              f"| false episodes per hour of held-out nominal driving (95 % bound) | {f['false_per_hour']:.2f} "
              f"({f['false_per_hour_upper95']:.2f}) over {f['nominal_hours']:.2f} h |"]
    c = record.get("closed_loop") or {}
    if c:
        lines += ["", "### Closed loop: `--monitor act` against `warn` (which drives exactly like `off`)", "",
                  "| figure | warn | act |", "|---|---|---|",
                  f"| misbehaviours on the {c['failing_runs']} failing runs | {c['misbehaviours_off']} | "
                  f"{c['misbehaviours_act']} ({pct(c['prevented'])} prevented) |",
                  f"| stuck or wrong-way take-overs there | {c['stuck_or_wrong_way_off']} | "
                  f"{c['stuck_or_wrong_way_act']} |"]
        for key, label, unit in (("eta", "degree of autonomy, nominal", " %"), ("lap_time_s", "lap time, nominal",
                                 " s"), ("mean_speed_kmh", "mean speed, nominal", " km/h")):
            off, act, ch = c[f"nominal_{key}_off"], c[f"nominal_{key}_act"], c[f"nominal_{key}_change"]
            if off is not None and act is not None:
                change = f" ({100 * ch:+.1f} %)" if ch is not None else ""
                lines.append(f"| {label} ({c['nominal_runs']} runs) | {off:.2f}{unit} | {act:.2f}{unit}{change} |")
    monitors = record.get("monitors") or []
    if len(monitors) > 1:
        lines += ["", "### Monitors compared on the same drives", "",
                  "| monitor | recall 1 / 2 / 3 s | recall 4-6 s | F3 1-3 s | lead >= 1 s | false per hour (95 %) |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {m['monitor']} | {m['r1']} / {m['r2']} / {m['r3']} | {m['r46']} | {m['f3']} | {m['lead1']} | "
                  f"{m['false']} |" for m in monitors]
    cost = record.get("cost")
    if cost:
        lines += ["", "### Cost: drive_server's pipeline per frame, monitor off and on in one run", "",
                  "| | p50 | p99 |", "|---|---|---|",
                  f"| monitor off | {cost['off']['p50_ms']:.3f} ms | {cost['off']['p99_ms']:.3f} ms |",
                  f"| monitor on (act) | {cost['on']['p50_ms']:.3f} ms | {cost['on']['p99_ms']:.3f} ms |",
                  f"| added | {cost['added']['p50_ms']:.3f} ms | {cost['added']['p99_ms']:.3f} ms |"]
    return "\n".join(lines) + "\n"


def table_rows(record: dict[str, Any]) -> dict[str, list[dict[str, str]]]:
    """The tables' rows as text cells, for a results record (``tools.results`` renders rows of a record)."""
    f, c, cost = record["figures"]["all"], record.get("closed_loop") or {}, record.get("cost")

    def s(x: float | None) -> str:
        return "-" if x is None else f"{x:.1f} s"

    anchors = [{"monitor": f"ours: {record['monitor']['score']}, thresholds from other runs",
                "r1": pct(f["recall_at"]["1"]), "r2": pct(f["recall_at"]["2"]), "r3": pct(f["recall_at"]["3"]),
                "r46": pct(f["recall_4_6"]),
                "f3": f"{f['f3_1_3']:.2f}"}]
    anchors += [{"monitor": f"{a.monitor} (published, in-sample)", "r1": pct(a.recall_1), "r2": pct(a.recall_2),
                 "r3": pct(a.recall_3), "r46": "77.0 %" if a.monitor.startswith("SelfOracle") else "-",
                 "f3": "-" if a.f3 is None else f"{a.f3:.2f}"} for a in ANCHORS]
    deployment = [
        {"figure": "misbehaviours (runs with warn)", "value": f"{f['misbehaviours']}"},
        {"figure": "recall at a lead of at least 1 / 2 / 3 s",
         "value": " / ".join(pct(f["lead_recall_at"][k]) for k in ("1", "2", "3"))},
        {"figure": "median / p10 lead of the first warning",
         "value": f"{s(f['lead_median_s'])} / {s(f['lead_p10_s'])}"},
        {"figure": "warning episodes followed by a misbehaviour within 10 s", "value": pct(f["lead_precision"])},
        {"figure": "false episodes per hour of held-out nominal driving (95 % bound)",
         "value": f"{f['false_per_hour']:.2f} ({f['false_per_hour_upper95']:.2f}) over {f['nominal_hours']:.1f} h"},
    ]
    closed = []
    if c:
        closed.append({"figure": f"misbehaviours on the {c['failing_runs']} perturbed and degraded runs",
                       "warn": f"{c['misbehaviours_off']}",
                       "act": f"{c['misbehaviours_act']} ({pct(c['prevented'])} prevented)"})
        closed.append({"figure": "stuck or wrong-way take-overs there", "warn": f"{c['stuck_or_wrong_way_off']}",
                       "act": f"{c['stuck_or_wrong_way_act']}"})
        for key, label, unit in (("eta", "degree of autonomy, held-out nominal", " %"),
                                 ("lap_time_s", "lap time, held-out nominal", " s"),
                                 ("mean_speed_kmh", "mean speed, held-out nominal", " km/h")):
            off, act, ch = c[f"nominal_{key}_off"], c[f"nominal_{key}_act"], c[f"nominal_{key}_change"]
            if off is not None and act is not None:
                closed.append({"figure": label, "warn": f"{off:.2f}{unit}",
                               "act": f"{act:.2f}{unit}" + (f" ({100 * ch:+.1f} %)" if ch is not None else "")})
    costs = []
    if cost:
        costs = [{"monitor": name, "p50": f"{cost[key]['p50_ms']:.3f} ms", "p99": f"{cost[key]['p99_ms']:.3f} ms"}
                 for name, key in (("off", "off"), ("on (act)", "on"), ("added", "added"))]
    return {"anchors": anchors, "deployment": deployment, "closed_loop": closed, "cost": costs,
            "sweep": record.get("sweep", []),
            "monitors": [{k: v for k, v in row.items() if k != "figures"} for row in record.get("monitors", [])],
            "in_sample": [{k: v for k, v in row.items() if k != "figures"} for row in record.get("in_sample", [])]}


#: The tables of the benchmark's results record (``results/monitor-eval.json``), over ``runs.0.output.rows``.
RESULT_TABLES = {
    "anchors": {"rows": "runs.0.output.rows.anchors",
                "columns": [["monitor", "{monitor}"], ["recall 1 s", "{r1}"], ["recall 2 s", "{r2}"],
                            ["recall 3 s", "{r3}"], ["recall 4-6 s", "{r46}"], ["F3 1-3 s", "{f3}"]]},
    "anchors-protocol": {"rows": "runs.0.output.rows.in_sample", "caption": "short",
                         "columns": [["monitor", "{monitor}"], ["threshold", "{threshold}"],
                                     ["recall 1 / 2 / 3 s", "{r1} / {r2} / {r3}"], ["recall 4-6 s", "{r46}"],
                                     ["precision 1-3 s", "{p13}"], ["F3 1-3 s", "{f3}"],
                                     ["nominal windows alarmed", "{nominal_alarmed}"]]},
    "monitors": {"rows": "runs.0.output.rows.monitors", "caption": "short",
                 "columns": [["monitor", "{monitor}"], ["recall 1 / 2 / 3 s", "{r1} / {r2} / {r3}"],
                             ["recall 4-6 s", "{r46}"], ["F3", "{f3}"], ["lead >= 1 s", "{lead1}"],
                             ["false per hour (95 % bound)", "{false}"]]},
    "deployment": {"rows": "runs.0.output.rows.deployment", "caption": "short",
                   "columns": [["figure", "{figure}"], ["value", "{value}"]]},
    "closed-loop": {"rows": "runs.0.output.rows.closed_loop", "caption": "short",
                    "columns": [["figure", "{figure}"], ["--monitor warn", "{warn}"], ["--monitor act", "{act}"]]},
    "sweep": {"rows": "runs.0.output.rows.sweep", "caption": "short",
              "columns": [["monitor", "{monitor}"], ["warning threshold", "{threshold}"],
                          ["recall 1 / 2 / 3 s", "{r123}"], ["lead >= 1 s", "{lead1}"], ["F3", "{f3}"],
                          ["false per hour (95 % bound)", "{false}"]]},
    "cost": {"rows": "runs.0.output.rows.cost", "caption": "short",
             "columns": [["monitor", "{monitor}"], ["p50", "{p50}"], ["p99", "{p99}"]]},
}


def results_record(record: dict[str, Any], command: str, machine: str, date: str, source: str) -> dict[str, Any]:
    """The benchmark's record as a Results page record (``tools.results``): its figures, not its runs."""
    keep = {k: v for k, v in record.items() if k != "figures"} | {"figures": {"all": record["figures"]["all"]}}
    return {"title": "rbc monitor eval: the misbehaviour monitor on the headless simulator (held-out nominal "
                     "driving, perturbed runs, degraded models), beside the published monitors",
            "provenance": "transcribed", "source": source, "date": date, "code_version": record["code_version"],
            "machine": machine, "runs": [{"command": command, "output": keep}], "tables": RESULT_TABLES}
