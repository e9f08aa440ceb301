"""Turn evaluation summaries into the paper's tables (Markdown) and plots."""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tools.evaluate.experiments import AUTONOMY_RULE, EXPERIMENTS, Experiment
from tools.evaluate.paper import PAPER_TABLE9

if TYPE_CHECKING:
    from tools.evaluate.evalrecord import EvalRun

log = logging.getLogger(__name__)


def _signed(x: float, unit: str) -> str:
    text = f"{x:+.1f}" if unit == "cd" else f"{x:+.0f}"
    return text + ("°" if unit == "°" else "")


def _range_text(lower: str, upper: str, unit: str) -> str:
    return f"[{lower}, {upper}]" + (" cd" if unit == "cd" else "")


def format_range(lower: float, upper: float, unit: str) -> str:
    """A range of offsets in the paper's notation, e.g. ``[-0.2, +0.3] cd`` or ``[-20°, +10°]``."""
    return _range_text(_signed(lower, unit), _signed(upper, unit), unit)


def format_cell(entry: dict[str, Any] | None) -> str:
    """One measured Table 9 cell in the paper's notation."""
    if entry is None:
        return "n/a"
    if entry["measure"] == "worlds":
        from tools.evaluate.worlds import format_worlds

        return format_worlds(entry)
    if entry["measure"] == "eta":
        parts = []
        for stats in entry["values"].values():
            parts.append(f"{stats['mean']:.1f} ± {stats['std']:.1f}")
        if len(parts) > 1:
            keys = ", ".join(entry["values"])
            return f"η{{{keys}}} = {' / '.join(parts)} %"
        return f"η = {parts[0]} %"
    unit = entry.get("unit", "")
    if entry["measure"] == "range":
        if entry.get("empty"):
            return "none (fails without variation)"
        lo, hi = entry.get("lower", {}), entry.get("upper", {})

        def bound(side: dict[str, Any], mark: str) -> str:
            if not side or side.get("limit") is None:
                return "?"
            text = _signed(side["limit"] - entry["origin"], unit)
            return f"{mark}{text}" if side.get("hit_cap") else text

        return _range_text(bound(lo, "≤"), bound(hi, "≥"), unit)
    up = entry.get("upper", {})
    if not up or up.get("limit") is None:
        return f"< {entry['origin']:.0f} {unit}"
    return f"{'≥ ' if up.get('hit_cap') else ''}{up['limit']:.0f} {unit}"


def shown_experiments(summaries: Iterable[dict[str, Any]]) -> list[Experiment]:
    """The paper's experiments, and those beyond it that one of ``summaries`` ran (tables keep their rows)."""
    summaries = list(summaries)
    return [e for e in EXPERIMENTS if e.paper or any(e.key in s for s in summaries)]


def table9(summaries: dict[str, dict[str, Any]], with_paper: bool = True) -> str:
    """Markdown in the layout of the paper's Table 9: one column per behavior (plus the paper's)."""
    behaviors = list(summaries)
    head = ["Experiment"]
    for b in behaviors:
        head.append(f"{b.capitalize()} (measured)")
        if with_paper:
            head.append(f"{b.capitalize()} (paper)")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for exp in shown_experiments(summaries.values()):
        row = [exp.title]
        for b in behaviors:
            entry = summaries[b].get(exp.key)
            row.append(format_cell(entry) if exp.applies_to(b) else "…")
            if with_paper:
                row.append(PAPER_TABLE9[exp.key][b])
        lines.append("| " + " | ".join(row) + " |")
    lines.append("")
    lines.append(f"~100 % means: {AUTONOMY_RULE}. η: mean ± std over seeds. Ranges are offsets from the default "
                 "(light intensity 1.0, light direction 0°, yaw 0°); ≤/≥ mark a search that reached its cap."
                 + (" Unseen worlds: one run per generated evaluation world, mean ± std over worlds."
                    if any("unseen_worlds" in s for s in summaries.values()) else ""))
    return "\n".join(lines) + "\n"


def plot_points(exp: Experiment, entry: dict[str, Any], records: Sequence[Mapping[str, Any]]
                ) -> list[tuple[float, float, bool]]:
    """(value, eta, autonomous) of every run of a searched experiment, in order of value.

    Ranges are drawn as offsets from the default, and include the no-variation run they start from.
    """
    runs = [r for r in records if r["experiment"] == exp.key]
    if not runs:
        return []
    origin = entry["origin"] if exp.measure == "range" else 0
    base = [r for r in records if r["experiment"] == "no_variation"]
    if exp.measure == "range" and base:
        runs.append({**min(base, key=lambda r: r["seed"]), "value": origin})
    runs.sort(key=lambda r: r["value"])
    return [(r["value"] - origin, sum(lap["eta"] for lap in r["laps"]) / max(1, len(r["laps"])), r["autonomous"])
            for r in runs]


def plot_experiments(summary: dict[str, Any], records: Sequence[EvalRun], out_dir: Path) -> list[Path]:
    """eta against each varied parameter (pass/fail marked). Needs matplotlib (the plots extra)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ModuleNotFoundError:
        log.warning("matplotlib is not installed: skipping plots (pip install '.[plots]')")
        return []
    written = []
    for exp in EXPERIMENTS:
        entry = summary.get(exp.key)
        if not entry or entry["measure"] == "eta":
            continue
        if entry["measure"] == "worlds":
            from tools.evaluate.worlds import plot_worlds

            written += [p for p in [plot_worlds(entry, out_dir / f"{exp.key}.png", plt)] if p]
            continue
        points = plot_points(exp, entry, records)
        if not points:
            continue
        xs, ys, ok = (list(v) for v in zip(*points, strict=True))
        fig, ax = plt.subplots(figsize=(6, 3.2), dpi=110)
        ax.plot(xs, ys, "-", color="0.6", zorder=1)
        ax.scatter([x for x, o in zip(xs, ok, strict=True) if o], [y for y, o in zip(ys, ok, strict=True) if o],
                   color="tab:green", label="~100 % (no take-over)", zorder=2)
        ax.scatter([x for x, o in zip(xs, ok, strict=True) if not o],
                   [y for y, o in zip(ys, ok, strict=True) if not o], color="tab:red", marker="x",
                   label="take-over(s)", zorder=2)
        ax.set(xlabel=exp.axis or f"{exp.title} ({exp.unit})", ylabel="degree of autonomy η (%)", title=exp.title,
               ylim=(min(0, min(ys) - 5), 105))
        ax.grid(alpha=0.3)
        ax.legend(loc="lower left", fontsize=8)
        fig.tight_layout()
        path = out_dir / f"{exp.key}.png"
        fig.savefig(path)
        plt.close(fig)
        written.append(path)
    return written
