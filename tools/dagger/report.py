"""DAgger against behavioral cloning at equal expert frames: the table, the curve and the target's verdict.

Reads two finished (or partly finished) ``rbc dagger`` runs, one ``--baseline bc``, from their ``summary.json``
and writes ``comparison.md`` (one row per budget, both methods side by side), ``comparison.json`` and
``curve.png`` (eta on the unseen worlds against expert frames: mean and worst world, both methods; the built-in
tracks beside it).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from protocol.errors import BadValue
from protocol.runrecords import code_version, read_json, write_json, write_text
from tools.dagger.config import DaggerConfig
from tools.dagger.records import (
    BestRound,
    ComparedRow,
    CurveKey,
    SummaryDocument,
    SummaryRow,
    Verdict,
    VerdictFrames,
)
from tools.dagger.summary import SUMMARY_JSON
from tools.sim.driving.rules import TARGET_ETA

CURVE = "curve.png"
#: The built-in tracks the curve draws: (summary key, name, marker, line).
CURVE_TRACKS: tuple[tuple[CurveKey, str, str, str], ...] = (("lake_eta", "lake", "o", "-"),
                                                             ("mountain_eta", "mountain", "^", ":"))


def load_rows(folder: Path) -> tuple[str, list[SummaryRow], SummaryDocument]:
    path = Path(folder) / SUMMARY_JSON
    if not path.is_file():
        raise BadValue(f"{folder}: no {SUMMARY_JSON} (not an rbc dagger output folder, or no round finished yet)")
    summary: SummaryDocument = read_json(path)
    return summary["mode"], summary["rounds"], summary


def frames_to_target(rows: Sequence[SummaryRow]) -> int | None:
    """The fewest expert frames after which every unseen world was driven at >= 95 % (None: never)."""
    return next((r["expert_frames"] for r in rows if r.get("worlds_n") and r["worlds_at_target"] == r["worlds_n"]),
                None)


def verdict(dagger: Sequence[SummaryRow], bc: Sequence[SummaryRow]) -> Verdict:
    """Issue #46's target: DAgger drives every unseen world at >= 95 % with at most a third of the expert frames
    behavioral cloning needs for the same (or, where BC never gets there, a third of the most it was given)."""
    d, b = frames_to_target(dagger), frames_to_target(bc)
    most_bc = max((r["expert_frames"] for r in bc), default=0)
    bound = b if b is not None else most_bc
    met = d is not None and bound > 0 and 3 * d <= bound
    head: VerdictFrames = {"target_eta": TARGET_ETA, "dagger_frames": d, "bc_frames": b, "bc_most_frames": most_bc,
                           "bc_reached": b is not None, "met": met}
    if d is None:
        best = max(dagger, key=lambda r: (r.get("worlds_at_target", 0), r.get("worlds_worst", 0)), default=None)
        top: BestRound | None = None if best is None else {
            "expert_frames": best["expert_frames"], "worlds_at_target": best.get("worlds_at_target"),
            "worlds_n": best.get("worlds_n"), "worst": best.get("worlds_worst")}
        text = (f"missed: DAgger drove every unseen world at >= {TARGET_ETA:.0f} % at none of its budgets "
                f"(best: {top['worlds_at_target']}/{top['worlds_n']} worlds, worst {top['worst']:.1f} %, at "
                f"{top['expert_frames']:,} frames)" if top else "missed: no DAgger round")
        return {**head, "dagger_best": top, "text": text}
    ratio = d / bound if bound else float("inf")
    bc_text = f"BC at {b:,}" if b is not None else f"BC never within {most_bc:,}"
    text = (f"{'met' if met else 'missed'}: DAgger at {d:,} expert frames, {bc_text} "
            f"({'at most ' if b is None else ''}{ratio:.2f}x the frames; the target is <= 0.33x)")
    return {**head, "ratio": round(ratio, 3), "text": text}


def compare(dagger_dir: Path, bc_dir: Path, out: Path) -> dict[str, object]:
    """Write ``out/comparison.md``, ``comparison.json`` and ``curve.png``; return the comparison."""
    mode_d, dagger, sum_d = load_rows(dagger_dir)
    mode_b, bc, sum_b = load_rows(bc_dir)
    if (mode_d, mode_b) != ("dagger", "bc"):
        raise BadValue(f"compare a dagger run with a bc run: {dagger_dir} is {mode_d}, {bc_dir} is {mode_b}",
                       "rbc dagger --compare DAGGER_OUT BC_OUT --out REPORT (the BC run made with --baseline bc)")
    who = ("mode", "beta0", "beta_decay", "budgets")  # what may differ: who drove, and how many frames
    d_cfg = {k: v for k, v in DaggerConfig.from_dict(sum_d["config"]).to_dict().items() if k not in who}
    b_cfg = {k: v for k, v in DaggerConfig.from_dict(sum_b["config"]).to_dict().items() if k not in who}
    if d_cfg != b_cfg:
        diff = sorted(k for k in d_cfg if d_cfg[k] != b_cfg.get(k))
        raise BadValue(f"the two runs differ in more than who drove: {', '.join(diff)}",
                       "run both with the same --recipe, --seed, evaluation worlds and tracks")
    out.mkdir(parents=True, exist_ok=True)
    found = verdict(dagger, bc)
    result = {"verdict": found, "rows": merged_rows(dagger, bc), "dagger_dir": str(dagger_dir),
              "bc_dir": str(bc_dir), "config": sum_d["config"], "bc_config": sum_b["config"],
              "seed": sum_d["seed"], "code_version": code_version()}
    write_json(out / "comparison.json", result)
    write_text(out / "comparison.md", comparison_table(dagger, bc) + "\n" + found["text"] + "\n")
    plot_curve(dagger, bc, out / CURVE)
    return result


def merged_rows(dagger: Sequence[SummaryRow], bc: Sequence[SummaryRow]) -> list[ComparedRow]:
    """Both methods' rounds by expert frames (BC first at equal frames), each named with its beta."""
    rows: list[ComparedRow] = [
        {**r, "method": f"DAgger (β {r['beta']:.3g})" if r["beta"] < 1 else "DAgger (expert only)"} for r in dagger]
    rows += [{**r, "method": "BC"} for r in bc]
    for row in rows:
        row["every_world"] = bool(row.get("worlds_n")) and row.get("worlds_at_target") == row["worlds_n"]
    return sorted(rows, key=lambda r: (r["expert_frames"], r["mode"] != "bc"))


#: The comparison's columns: header, then a format over a merged row (8 columns, the site's widest table).
COLUMNS = (("expert frames", "{expert_frames:,}"), ("method", "{method}"),
           ("worlds: mean η", "{worlds_mean:.1f} %"), ("worst world", "{worlds_worst:.1f} %"),
           ("worlds ≥ 95 %", "{worlds_at_target}/{worlds_n}"), ("take-overs", "{all_takeovers}"),
           ("lake η", "{lake_eta:.1f} %"), ("mountain η", "{mountain_eta:.1f} %"))


def comparison_table(dagger: Sequence[SummaryRow], bc: Sequence[SummaryRow]) -> str:
    """One row per method and budget: the worlds' mean and worst eta, the worlds at >= 95 %, the take-overs on
    the worlds and tracks together, and each built-in track (a column a run lacks prints as "–")."""
    lines = ["| " + " | ".join(head for head, _ in COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in merged_rows(dagger, bc):
        cells = []
        for _, template in COLUMNS:
            try:
                cells.append(template.format(**row))
            except KeyError:
                cells.append("–")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_curve(dagger: Sequence[SummaryRow], bc: Sequence[SummaryRow], path: Path) -> Path:
    """eta against expert frames: the unseen worlds' mean and worst world (left), the worlds driven at >= 95 %
    (middle), lake and mountain (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, middle, right) = plt.subplots(1, 3, figsize=(15, 4.3), dpi=110)
    styles = {"dagger": ("tab:blue", "DAgger"), "bc": ("tab:orange", "BC")}
    both = [*dagger, *bc]
    n = next((r["worlds_n"] for r in both if r.get("worlds_n")), 0)
    for name, rows in (("bc", bc), ("dagger", dagger)):
        color, label = styles[name]
        xs = [r["expert_frames"] for r in rows]
        if rows and "worlds_mean" in rows[0]:
            left.plot(xs, [r["worlds_mean"] for r in rows], "-o", color=color, label=f"{label}: mean of the worlds")
            left.plot(xs, [r["worlds_worst"] for r in rows], "--s", color=color, label=f"{label}: worst world")
            middle.plot(xs, [r["worlds_at_target"] for r in rows], "-o", color=color, label=label)
        for key, track, marker, dash in CURVE_TRACKS:
            if rows and key in rows[0]:
                right.plot(xs, [r[key] for r in rows], dash + marker, color=color, label=f"{label}: {track}")
    frames = sorted({r["expert_frames"] for r in both})
    for ax, title in ((left, f"{n} unseen generated worlds (evaluation seeds)"),
                      (middle, f"unseen worlds driven at >= {TARGET_ETA:.0f} %"), (right, "built-in tracks")):
        if ax is middle:
            ax.axhline(n, color="0.4", linewidth=0.8, linestyle="-.", label=f"target: all {n}")
            ax.set(ylim=(-0.5, n + 0.5), ylabel="worlds")
            ax.set_yticks(range(0, n + 1, max(1, n // 4)))
        else:
            ax.axhline(TARGET_ETA, color="0.4", linewidth=0.8, linestyle="-.", label=f"target {TARGET_ETA:.0f} %")
            ax.set(ylabel="degree of autonomy η (%)")
        ax.set_xscale("log", base=2)
        ax.set_xticks(frames, [f"{f / 1000:g}k" if f >= 1000 else str(f) for f in frames])
        ax.minorticks_off()
        ax.set(xlabel="expert-labelled frames")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    low = min([r.get("worlds_worst", 100) for r in both] + [r.get(k, 100) for r in both for k, *_ in CURVE_TRACKS])
    for ax in (left, right):
        ax.set_ylim(max(0.0, low - 5), 101)
    fig.suptitle("DAgger against behavioral cloning at equal expert frames (rbc dagger)", fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
