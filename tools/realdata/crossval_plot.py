"""The picture of a cross-validation: each recording's closed-loop degree of autonomy, the fold model beside the
peer, one panel per track, the 95 % target drawn. Read from ``rbc data crossval --json``'s document (or a result
record's copy of it), so the docs' picture and a user's come from the same figures."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from protocol.runrecords import atomic_path
from tools.sim.driving.rules import TARGET_ETA

TRACKS = ("lake", "mountain", "jungle")


def plot_crossval(document: dict[str, Any], path: Path) -> Path:
    """Write the picture of ``document`` (``folds`` and optionally ``peer``, each with its ``recordings``) to
    ``path``; recordings without a closed loop are left out. Written whole or not at all."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folds = [r for r in document["folds"]["recordings"] if r.get("eta") is not None]
    peer = {r["name"]: r for r in document.get("peer", {}).get("recordings", []) if r.get("eta") is not None}
    tracks = [t for t in TRACKS if any(r["track"] == t for r in folds)]
    if not tracks:
        raise ValueError("no recording was driven closed loop: nothing to draw")
    counts = [sum(r["track"] == t for r in folds) for t in tracks]
    fig, axes = plt.subplots(len(tracks), 1, figsize=(8, 1.2 + 0.24 * sum(counts) + 0.5 * len(tracks)),
                             gridspec_kw={"height_ratios": counts}, sharex=True, squeeze=False)
    low = min([r["eta"] for r in folds] + [p["eta"] for p in peer.values()] + [TARGET_ETA])
    for ax, track in zip(axes[:, 0], tracks, strict=True):
        mine = sorted((r for r in folds if r["track"] == track), key=lambda r: r["eta"])
        y = range(len(mine))
        ax.axvspan(TARGET_ETA, 100.5, color="#e8f5e9", zorder=0)
        ax.axvline(TARGET_ETA, color="#2e7d32", lw=1, ls="--", zorder=1)
        theirs = [(i, peer[r["name"]]["eta"]) for i, r in enumerate(mine) if r["name"] in peer]
        for i, eta in theirs:
            ax.plot([eta, mine[i]["eta"]], [i, i], color="#bbbbbb", lw=1, zorder=2)
        if theirs:
            ax.scatter([e for _, e in theirs], [i for i, _ in theirs], s=28, facecolors="white", edgecolors="#777777",
                       zorder=3)
        ax.scatter([r["eta"] for r in mine], list(y), s=30, color=["#1565c0" if r["eta"] >= TARGET_ETA else "#c62828"
                                                               for r in mine], zorder=4)
        ax.set_yticks(list(y), [r["name"] for r in mine], fontsize=8)
        ax.set_ylim(-0.7, len(mine) - 0.3)
        reached = sum(r["eta"] >= TARGET_ETA for r in mine)
        ax.set_title(f"{track}: {reached} of {len(mine)} at {TARGET_ETA:g} % or more", fontsize=10, loc="left")
        ax.grid(axis="x", color="#eeeeee", zorder=0)
    from matplotlib.lines import Line2D

    keys = [Line2D([], [], ls="", marker="o", color="#1565c0", label=f"fold model, {TARGET_ETA:g} % or more"),
            Line2D([], [], ls="", marker="o", color="#c62828", label="fold model, below")]
    if peer:
        keys.append(Line2D([], [], ls="", marker="o", markerfacecolor="white", markeredgecolor="#777777",
                           label="peer"))
    fig.legend(handles=keys, loc="upper center", ncol=len(keys), fontsize=8, frameon=False)
    axes[-1, 0].set_xlim(max(0.0, low - 3), 100.5)
    axes[-1, 0].set_xlabel("degree of autonomy, % (closed loop on the recorded drive, the driver never seen)")
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.35 / fig.get_figheight()))  # room for the legend above the panels
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
    return path
