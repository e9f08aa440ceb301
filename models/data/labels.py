"""Steering labels as a driver meant them: the centred moving average of keyboard taps."""

from __future__ import annotations

import numpy as np


def centred_average(values: np.ndarray, frames: int, weights: np.ndarray | None = None) -> np.ndarray:
    """Centred moving average over ``frames`` samples, counting only samples of nonzero ``weight``.

    Keyboard steering is a train of taps (~70 % exact zeros in the Udacity sample): the same road gets 0
    in one frame and -0.3 in the next, which no single-frame model can predict. Its average over about a
    second is what the driver meant. Near the ends the window holds fewer samples; where it holds none
    of weight > 0 the value is returned as it was. The result has the length of ``values`` whatever
    ``frames`` is (a window longer than the log averages what there is).
    """
    v = np.asarray(values, np.float64)
    w = np.ones_like(v) if weights is None else np.asarray(weights, np.float64)
    kernel = np.ones(max(1, frames))
    pad = max(0, len(kernel) - len(v))  # np.convolve "same" returns the longer input's length
    vp, wp = np.pad(v * w, pad), np.pad(w, pad)
    total = np.convolve(vp, kernel, mode="same")[pad:pad + len(v)]
    count = np.convolve(wp, kernel, mode="same")[pad:pad + len(v)]
    return np.where(count > 0, total / np.maximum(count, 1e-9), v)
