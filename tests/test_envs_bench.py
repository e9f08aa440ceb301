"""rbc env-bench: steps per second, CPU milliseconds per step and peak memory of rbc/Drive-v0, alone and in an
AsyncVectorEnv (the figures are measured by the command, not asserted here)."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("gymnasium", reason="the gym extra is not installed (pip install -e '.[gym]')")

from tools.bench.env_vector import VectorBenchResult, bench_vector  # noqa: E402
from tools.bench.envs import HEADER, EnvBenchResult, bench_env  # noqa: E402


def test_a_row_gives_cpu_ms_per_step_and_the_peak_memory():
    """Was: rows gave steps per second only; CPU ms per step and peak memory are the figures contention spares."""
    row = EnvBenchResult("lake", 1, True, 100, 700.0, 800.0, 0, peak_rss_mb=301.4).row()
    assert row.split()[-3:] == ["1.250", "301", "0"]
    assert "CPU ms" in HEADER and "peak MB" in HEADER
    assert EnvBenchResult("lake", 1, True, 100, 700.0, 800.0, 0).row().split()[-2] == "-"  # not measured alone
    result = bench_env("lake", steps=3, repeats=1, warmup=1)
    assert result.cpu_ms_per_step > 0 and math.isclose(result.cpu_ms_per_step * result.cpu_steps_per_s, 1000.0)


def test_the_vector_lines_give_each_process_its_cpu_and_memory():
    result = VectorBenchResult(2, 100, 800.0, 1.25, 1400.0, (1.3, 1.4), 0.2, (290.0, 291.0), (110.0, 111.0),
                               (105.0,))
    assert math.isclose(result.scaling, 1.75) and math.isclose(result.cpu_bound, 2 * 1.25 / 1.6)
    text = "\n".join(result.lines())
    for part in ("1.75x one env", "1.300, 1.400", "0.200 CPU ms per vector step", "1.56x", "peak RSS 290, 291 MB",
                 "PSS 110, 111 MB", "main process PSS 105 MB"):
        assert part in text, part


@pytest.mark.slow
def test_the_vector_bench_runs_its_workers_forked_from_a_fresh_process():
    """Was: the workers were spawned (the default of a spawned process), did not import the env and failed."""
    result = bench_vector("lake", envs=2, steps=3, warmup=1)
    assert result.vector_steps_per_s > 0 and result.one_steps_per_s > 0
    assert len(result.worker_cpu_ms) == 2 and len(result.worker_peak_rss_mb) == 2
