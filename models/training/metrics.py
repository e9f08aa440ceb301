"""How good a steering prediction is, in figures a reader can judge: MSE, Pearson r, and the MSE of
always predicting 0 (the baseline a model must beat: about 70 % of keyboard steering labels are 0)."""

from __future__ import annotations

import numpy as np


def pearson_r(pred: np.ndarray, truth: np.ndarray) -> float:
    """Correlation of prediction and label; nan when either is constant."""
    p, t = np.asarray(pred, np.float64).ravel(), np.asarray(truth, np.float64).ravel()
    if len(p) < 2 or p.std() == 0 or t.std() == 0:
        return float("nan")
    return float(np.corrcoef(p, t)[0, 1])


def steering_metrics(pred: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """``mse``, ``r`` and ``zero_mse`` (always 0) over the given frames, plus their count ``n``."""
    p, t = np.asarray(pred, np.float64).ravel(), np.asarray(truth, np.float64).ravel()
    return {"n": int(len(t)), "mse": float(np.mean((p - t) ** 2)) if len(t) else float("nan"),
            "r": pearson_r(p, t), "zero_mse": float(np.mean(t ** 2)) if len(t) else float("nan")}


def metrics_by_group(pred: np.ndarray, truth: np.ndarray, groups: np.ndarray) -> dict[int, dict[str, float]]:
    """:func:`steering_metrics` of each group (e.g. each held-out recording), plus ``beats_zero``."""
    out = {}
    for g in np.unique(groups):
        m = steering_metrics(np.asarray(pred)[groups == g], np.asarray(truth)[groups == g])
        out[int(g)] = {**m, "beats_zero": m["mse"] < m["zero_mse"]}
    return out


def format_metrics(m: dict[str, float]) -> str:
    return f"MSE {m['mse']:.4f}, Pearson r {m['r']:.2f}, always-0 MSE {m['zero_mse']:.4f} ({m['n']} frames)"
