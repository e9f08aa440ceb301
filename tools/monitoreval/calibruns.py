"""The model's own nominal driving on the monitor's calibration worlds, for ``rbc monitor failures --set
calibration``: thresholds set on how the model itself drives (not the autopilot) on worlds that neither the
predictor's runs nor the benchmark use."""

from __future__ import annotations

from tools.monitoreval.runset import RunSpec

#: World seeds of the monitor's calibration runs (the bundled monitors' calibration worlds).
CALIBRATION_WORLDS = range(200, 230)


def calibration_runs(count: int) -> list[RunSpec]:
    """``count`` nominal runs of one lap, on the calibration worlds in turn (spawn seeds 800 + i)."""
    worlds = list(CALIBRATION_WORLDS)
    return [RunSpec(f"calibration-world{worlds[i % len(worlds)]}-{i}", "nominal", "none", 0.0,
                    f"world:{worlds[i % len(worlds)]}", seed=800 + i) for i in range(count)]
