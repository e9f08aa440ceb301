"""One run's monitor in words (``rbc sim``): its episodes, and which take-overs it foresaw and how early."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from tools.monitoreval.scoring import (
    DEFAULT_RULES,
    MISBEHAVIOUR_CAUSES,
    RunTrace,
    ScoringRules,
    first_warning_leads,
)

if TYPE_CHECKING:
    from tools.sim.driving.drivers import OnnxDriver
    from tools.sim.driving.scenario import RunResult


def run_trace(driver: OnnxDriver, result: RunResult, name: str = "run", group: str = "perturbed") -> RunTrace:
    t = np.array([when for when, _ in driver.readings], dtype=np.float64)
    level = np.array([int(r.level) if r is not None else 0 for _, r in driver.readings], dtype=np.uint8)
    takeovers = [(i.t, str(i.cause)) for lap in result.laps for i in lap.interventions]
    return RunTrace(name, group, t, level, takeovers, result.sim_time_s)


def monitor_summary(driver: OnnxDriver, result: RunResult, rules: ScoringRules = DEFAULT_RULES) -> str:
    monitor = driver.monitor
    assert monitor is not None, "a monitored run"
    spec, state = monitor.state.spec, monitor.state
    trace = run_trace(driver, result)
    found = first_warning_leads(trace, rules)
    foreseen = [x for x in found if x[2] is not None]
    head = (f"monitor {spec.score} ({driver.pipeline.config.monitor.mode.value}): {state.episodes['warning']} "
            f"warning(s), {state.episodes['alarm']} alarm(s)")
    if monitor.failed:
        head += f"; switched off: {monitor.failed}"
    # the take-overs a monitor can foresee: off the road, into a cone, a spin-out (MISBEHAVIOUR_CAUSES)
    text = f"take-overs foreseen: {len(foreseen)} of {len(found)}"
    if foreseen:
        text += " (leads " + ", ".join(f"{lead:.1f}" for *_, lead in foreseen) + " s)"
    skipped = sum(1 for _, c in trace.takeovers if c in MISBEHAVIOUR_CAUSES) - len(found)
    if skipped:
        text += f"; {skipped} more within {rules.settle_s:g} s of another"
    return f"{head}\n{text}"
