"""The picture of ``rbc realism``: real frames beside their nearest headless frames, and histograms."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from protocol.runrecords import atomic_path
from tools.realism.stats import Gap

#: Statistics drawn as histograms (the ones a look change moves most).
HISTOGRAMS = ("sky.brightness", "near_road.brightness", "near_road.saturation", "near_road.edges",
              "far_road.sharpness", "bonnet.brightness")


def draw(real: Sequence[np.ndarray], sim: Sequence[np.ndarray], pairs: Sequence[tuple[int, float]],
         real_stats: Sequence[dict[str, float]], sim_stats: Sequence[dict[str, float]], found: Sequence[Gap],
         title: str, path: Path, shown: int = 4) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    picks = np.linspace(0, len(real) - 1, min(shown, len(real))).round().astype(int)
    pair_rows = (len(picks) + 1) // 2
    fig = plt.figure(figsize=(12, 1.75 * pair_rows + 5.2), layout="constrained")
    top, bottom = fig.subfigures(2, 1, squeeze=False, height_ratios=[1.75 * pair_rows, 5.0])[:, 0]
    frames = top.subplots(pair_rows, 4, squeeze=False)
    for ax in frames.ravel():
        ax.axis("off")
    for n, i in enumerate(picks):
        k, dist = pairs[i]
        row, col = divmod(n, 2)
        for j, (img, label) in enumerate(((real[i], "real"), (sim[k], f"nearest headless (distance {dist:.0f})"))):
            ax = frames[row, 2 * col + j]
            ax.imshow(img)
            ax.set_title(label, fontsize=8)
    by_key = {g.key: g for g in found}
    for n, ax in enumerate(bottom.subplots(2, 3).ravel()):
        key = HISTOGRAMS[n]
        r = [s[key] for s in real_stats]
        m = [s[key] for s in sim_stats]
        bins = np.histogram_bin_edges(r + m, bins=24)
        ax.hist(r, bins=bins, alpha=0.6, label="real", color="tab:blue")
        ax.hist(m, bins=bins, alpha=0.6, label="headless", color="tab:orange")
        ax.set_title(f"{key}: gap {by_key[key].standardized:+.1f} spreads", fontsize=8)
        ax.tick_params(labelsize=7)
        if n == 0:
            ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path
