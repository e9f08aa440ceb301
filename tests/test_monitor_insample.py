"""The anchors' in-sample protocol: the gamma fit, the window means, and a threshold taken from nominal runs only."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from tools.monitoreval.insample import gamma_quantile_95, in_sample, markdown, window_means
from tools.monitoreval.runset import RunSpec
from tools.monitoreval.scoring import DEFAULT_RULES

HZ = 15


@pytest.mark.parametrize("shape, scale", [(0.8, 0.01), (2.0, 3.0), (9.0, 0.5)])
def test_gamma_quantile_matches_the_distribution(shape: float, scale: float) -> None:
    rng = np.random.default_rng(0)
    sample = rng.gamma(shape, scale, 200_000)
    truth = float(np.quantile(rng.gamma(shape, scale, 2_000_000), 0.95))
    assert gamma_quantile_95(sample) == pytest.approx(truth, rel=0.03)


def test_gamma_quantile_of_constant_values_is_the_value() -> None:
    assert gamma_quantile_95(np.full(10, 0.25)) == pytest.approx(0.25)
    with pytest.raises(ValueError):
        gamma_quantile_95(np.array([1.0]))


def test_window_means_are_the_servers_running_means() -> None:
    values = np.random.default_rng(1).random(50)
    window: deque[float] = deque(maxlen=HZ)
    expected = []
    for v in values:
        window.append(v)
        expected.append(sum(window) / len(window))
    assert window_means(values, HZ) == pytest.approx(expected)


def _run(scores: np.ndarray, takeovers: list[tuple[float, str]]) -> dict:
    t = np.arange(scores.size) / HZ
    return {"t": t.tolist(), "level": "0" * scores.size, "mean": window_means(scores, HZ).tolist(),
            "takeovers": takeovers, "sim_time_s": scores.size / HZ, "shadows": {"other": scores.tolist()}}


def _results(perturbed_scores: np.ndarray, nominal_level: float = 0.1) -> list:
    rng = np.random.default_rng(2)
    out = []
    for k in range(4):
        out.append((RunSpec(f"nominal-{k}", "nominal", "none", 0.0, "lake"), "warn",
                    _run(nominal_level + 0.02 * rng.random(60 * HZ), [])))
    dark = RunSpec("dark-0", "perturbed", "light", 0.2, "lake")
    out.append((dark, "warn", _run(perturbed_scores, [(40.0, "off_road")])))
    out.append((dark, "act", _run(perturbed_scores, [])))
    return out


def test_a_score_rising_before_the_failure_is_caught_at_every_slice() -> None:
    scores = np.full(60 * HZ, 0.1)
    scores[int(30 * HZ):int(40 * HZ)] = 1.0  # high for the 10 s before the take-over at 40 s
    rows = in_sample(_results(scores), DEFAULT_RULES, {None: ("driving", HZ), "other": ("shadow", HZ)})
    assert [r["monitor"] for r in rows] == [f"ours: {n}, the anchors' protocol (threshold in-sample)"
                                            for n in ("driving", "shadow")]
    for row in rows:
        f = row["figures"]
        assert f["misbehaviours"] == 1
        assert f["recall_at"] == {str(k): 1.0 for k in range(1, 7)}
        assert 0.1 < float(row["threshold"]) < 0.13  # within the nominal scores' spread
    assert "| ours: driving" in markdown({"in_sample": rows})


def test_the_threshold_comes_from_the_nominal_runs_only() -> None:
    quiet, loud = np.full(60 * HZ, 0.1), np.full(60 * HZ, 5.0)
    rules, mons = DEFAULT_RULES, {None: ("driving", HZ)}
    same = in_sample(_results(quiet), rules, mons)[0]["threshold"]
    assert in_sample(_results(loud), rules, mons)[0]["threshold"] == same  # the perturbed run never calibrates
    assert in_sample(_results(quiet, nominal_level=0.5), rules, mons)[0]["threshold"] != same
