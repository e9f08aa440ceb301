"""The picture of a monitored run: the one-second mean score over time against the warning and alarm thresholds,
the warning and alarm stretches shaded, each take-over marked with the lead of the warning that foresaw it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from tools.monitoreval.scoring import DEFAULT_RULES, ScoringRules, first_warning_leads
from tools.monitoreval.summary import run_trace

#: How much of the time axis a take-over's label takes: a closer one is put a row lower.
LABEL_WIDTH = 0.085

if TYPE_CHECKING:
    from tools.sim.driving.drivers import OnnxDriver
    from tools.sim.driving.scenario import RunResult


def plot_run(driver: OnnxDriver, result: RunResult, path: Path, title: str = "",
             rules: ScoringRules = DEFAULT_RULES) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from protocol.runrecords import atomic_path

    assert driver.monitor is not None, "a monitored run"
    spec = driver.monitor.state.spec
    t = np.array([w for w, _ in driver.readings])
    mean = np.array([r.mean if r is not None else np.nan for _, r in driver.readings])
    level = np.array([int(r.level) if r is not None else 0 for _, r in driver.readings])
    fig, ax = plt.subplots(figsize=(9, 4.2), dpi=110)
    for value, color in ((1, "#ffd23f"), (2, "#f25f5c")):
        on = level == value
        ax.fill_between(t, 0, 1, where=on, transform=ax.get_xaxis_transform(), color=color, alpha=0.25, lw=0,
                        label="warning" if value == 1 else "alarm")
    ax.plot(t, mean, color="#1d3557", lw=1.2, label=f"{spec.score} score (one-second mean)")
    ax.axhline(spec.warn, color="#e9a200", ls="--", lw=1, label=f"warning threshold {spec.warn:.3g}")
    ax.axhline(spec.alarm, color="#c0392b", ls="--", lw=1, label=f"alarm threshold {spec.alarm:.3g}")
    top = np.nanmax(mean) if np.isfinite(mean).any() else spec.alarm
    for lap in result.laps:  # every take-over, faintly (those right after another are not failures of their own)
        for intervention in lap.interventions:
            ax.axvline(intervention.t, color="grey", lw=0.6, alpha=0.6)
    span = float(t.max() - t.min()) if t.size else 1.0
    marks = first_warning_leads(run_trace(driver, result), rules)
    rows: list[int] = []
    placed: list[float] = []  # the latest label's time in each row: a label too close to one drops a row
    for when, _, _ in marks:
        row = next((k for k, last in enumerate(placed) if when - last > LABEL_WIDTH * span), len(placed))
        placed[row:row + 1] = [when]
        rows.append(row)
    # Room above the curve for the labels' rows (each about a tenth of the axes' height), so none hides another.
    ax.set_ylim(0, max(top, spec.alarm) * 1.05 / max(0.3, 1 - 0.11 * len(placed)))
    for (when, cause, lead), row in zip(marks, rows, strict=True):
        ax.axvline(when, color="black", lw=1.3)
        label = f"{cause.replace('_', ' ')}" + (f"\n{lead:.1f} s ahead" if lead is not None else "\nmissed")
        ax.annotate(label, (when, 1), xycoords=("data", "axes fraction"), xytext=(3, -3 - 21 * row),
                    textcoords="offset points", fontsize=7, va="top",
                    bbox={"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.8})
        if lead is not None:
            ax.annotate("", xy=(when, spec.alarm), xytext=(when - lead, spec.alarm),
                        arrowprops={"arrowstyle": "<->", "color": "black", "lw": 1})
    ax.set_xlabel("simulated time, s")
    ax.set_ylabel("score")
    ax.set_title(title or f"{driver.name}: misbehaviour monitor over one run", fontsize=10)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=5, frameon=False)
    ax.set_xlim(t.min() if t.size else 0, t.max() if t.size else 1)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format=Path(path).suffix.lstrip(".") or "png")
    plt.close(fig)
    return Path(path)
