"""The searched ranges of several models as bars, one panel per range experiment (Table 10 as a picture).

A bar spans the offsets at which the model still drove with no take-over; an arrow marks a side
whose search reached its cap (the true limit lies further out); the dashed lines are the caps.
The paper's ranges, where it gives them, are drawn hatched for comparison.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from protocol.runrecords import atomic_path
from tools.evaluate.experiments import EXPERIMENTS
from tools.evaluate.paper import PAPER_TABLE10_RANGES

if TYPE_CHECKING:
    from tools.evaluate.compare import Column

log = logging.getLogger(__name__)


def measured_range(entry: dict[str, Any] | None) -> tuple[float, float, bool, bool] | None:
    """(lower offset, upper offset, lower hit its cap, upper hit its cap), or None if empty or unknown."""
    if not entry or entry.get("measure") != "range" or entry.get("empty"):
        return None
    lo, hi = entry.get("lower") or {}, entry.get("upper") or {}
    if lo.get("limit") is None or hi.get("limit") is None:
        return None
    origin = entry["origin"]
    return lo["limit"] - origin, hi["limit"] - origin, bool(lo.get("hit_cap")), bool(hi.get("hit_cap"))


def plot_ranges(columns: Sequence[Column], path: Path, with_paper: bool = True) -> Path | None:
    """Draw the chart for ``columns`` (label + eval summary each); None without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ModuleNotFoundError:
        log.warning("matplotlib is not installed: skipping the range chart (pip install '.[plots]')")
        return None
    exps = [e for e in EXPERIMENTS if e.measure == "range"]
    paper = list(PAPER_TABLE10_RANGES.items()) if with_paper else []
    rows = [(c["label"], c["summary"]) for c in columns]
    n = len(rows) + len(paper)
    fig, axes = plt.subplots(1, len(exps), figsize=(4.2 * len(exps), 0.55 * n + 1.4), dpi=110, sharey=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, exp in zip(axes, exps, strict=True):
        caps = None
        for i, (_, summary) in enumerate(rows):
            entry = summary.get(exp.key)
            y = n - 1 - i
            rng = measured_range(entry)
            if entry and entry.get("caps"):
                caps = [c - entry["origin"] for c in entry["caps"]]
            if rng is None:
                ax.text(0, y, "none", ha="center", va="center", fontsize=8, color="tab:red")
                continue
            lo, hi, lo_cap, hi_cap = rng
            ax.barh(y, hi - lo, left=lo, height=0.6, color=colors[i % len(colors)], alpha=0.85)
            for x, capped, marker in ((lo, lo_cap, "<"), (hi, hi_cap, ">")):
                if capped:
                    ax.plot(x, y, marker=marker, color="black", markersize=7)
        for j, (_, ranges) in enumerate(paper):
            y = n - 1 - len(rows) - j
            if exp.key in ranges:
                lo, hi = ranges[exp.key]
                ax.barh(y, hi - lo, left=lo, height=0.6, color="white", edgecolor="0.4", hatch="///")
        if caps:
            for c in caps:
                ax.axvline(c, color="0.5", linestyle="--", linewidth=0.8)
            margin = 0.06 * (max(caps) - min(caps))
            ax.set_xlim(min(caps) - margin, max(caps) + margin)
        ax.axvline(0, color="black", linewidth=0.6)
        ax.set_title(exp.title.replace("variation", "").strip(), fontsize=10)
        ax.set_xlabel(f"offset from the default ({exp.unit})")
        ax.grid(axis="x", alpha=0.3)
    labels = [label for label, _ in rows] + [label for label, _ in paper]
    axes[0].set_yticks(range(n - 1, -1, -1), labels, fontsize=9)
    fig.suptitle("Ranges with no take-over (arrow: the search reached its cap; dashed: caps; hatched: paper)",
                 fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path
