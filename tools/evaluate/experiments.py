"""The robustness experiments and their scoring rules, as data (like CARLA's statistics manager).

Changing what "~100 %" means, a step size or a cap is an edit of this table, not of the runner.
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from protocol.facts import BEHAVIORS

#: The paper reports ranges "for which the ego vehicle exhibited ~100% autonomy". We define it once:
AUTONOMY_RULE = "no take-over in any lap of the run (degree of autonomy 100 %)"


def is_autonomous(run: Mapping[str, Any]) -> bool:  # a run's record (EvalRun), journaled by any version
    """The single definition of "~100 %": no take-over in any lap, and every lap completed."""
    laps = run["laps"]
    return bool(laps) and all(lap["completed"] and not lap["interventions"] for lap in laps)


@dataclass(frozen=True)
class BehaviorSetup:
    """Where a behavior was trained: its track and, for collision avoidance, the training cones."""

    track: str
    cones: int = 0
    cone_seed: int = 0


#: Training scenes of the bundled models (rbc collect uses the same cone seed for collision data).
TRAINING_CONE_SEED = 1
#: A value an experiment varies (cones, a fraction, a switch; None where it varies nothing).
AxisValue = float | int | bool | None
SETUPS: dict[str, BehaviorSetup] = {
    "simplistic": BehaviorSetup("lake"),
    "rigorous": BehaviorSetup("mountain"),
    "collision": BehaviorSetup("lake", cones=20, cone_seed=TRAINING_CONE_SEED),
}


@dataclass(frozen=True)
class Experiment:
    """One row of Table 9.

    measure:
      ``eta``   -- degree of autonomy (mean +- std over seeds) for each value in ``values``;
      ``range`` -- step outward from ``origin`` by ``step`` until the first non-autonomous run,
                   within ``[lower_cap, upper_cap]``; reported relative to ``origin``;
      ``max``   -- like ``range`` but upward only, reported as an absolute value;
      ``worlds`` -- eta of one run per generated world (mean +- std over worlds, and the worst world).

    ``paper`` False marks an experiment beyond the paper: not run unless asked for, labelled as such.
    """

    key: str
    title: str
    measure: Literal["eta", "range", "max", "worlds"]
    parameter: str | None = None  # the ScenarioConfig field that is varied
    values: tuple[AxisValue, ...] = (None,)
    origin: float = 0.0
    step: float = 0.0
    lower_cap: float = 0.0
    upper_cap: float = 0.0
    unit: str = ""
    behaviors: tuple[str, ...] = BEHAVIORS
    realtime: bool = False
    fixed: dict[str, Any] = field(default_factory=dict)  # other ScenarioConfig overrides
    axis: str = ""  # what a plot's x axis says, in words with the unit
    paper: bool = True  # one of the paper's eight (run by default)

    def applies_to(self, behavior: str) -> bool:
        return behavior in self.behaviors


# Caps sit a little beyond the widest ranges the paper reports (Tables 9 and 10: +1.2 cd, +-30 deg,
# -55 deg yaw, 100 km/h), so a search that reaches one reports "at least" instead of running on.

#: Cone layouts for the obstacle variation: new positions, unlike the training layout.
TEST_CONE_SEED = 1001

EXPERIMENTS: tuple[Experiment, ...] = (
    Experiment("no_variation", "No variation", "eta"),
    Experiment("obstacles", "Scene obstacle variation", "eta", "cones", values=(20, 10, 0),
               behaviors=("collision",), fixed={"cone_seed": TEST_CONE_SEED}),
    Experiment("light_intensity", "Scene light intensity variation", "range", "light_intensity",
               origin=1.0, step=0.1, lower_cap=0.1, upper_cap=2.5, unit="cd",
               axis="change of light intensity from the default 1.0 (cd)"),
    Experiment("light_direction", "Scene light direction variation", "range", "light_direction_deg",
               origin=0.0, step=1.0, lower_cap=-35.0, upper_cap=35.0, unit="°",
               axis="sun direction, rotated from the default (degrees)"),
    Experiment("position", "Vehicle position variation", "eta", "spawn_fraction", values=(0.5,)),
    Experiment("orientation", "Vehicle orientation variation", "range", "yaw_offset_deg",
               origin=0.0, step=5.0, lower_cap=-90.0, upper_cap=90.0, unit="°",
               axis="heading of the car at the start, off the road's direction (degrees, + = left)"),
    Experiment("heading_inversion", "Vehicle heading inversion", "eta", "reverse", values=(True,)),
    Experiment("speed_limit", "Vehicle speed limit variation", "max", "speed_limit_kmh",
               origin=30.0, step=5.0, lower_cap=30.0, upper_cap=100.0, unit="km/h", realtime=True,
               axis="speed limit (km/h)"),
    # Beyond the paper: generalisation to worlds never trained on, from the reserved evaluation seeds
    # (tools.sim.worldgen); one run per world at the first seed (the nominal spawn pose), the behavior's cones.
    Experiment("unseen_worlds", "Unseen generated worlds (beyond the paper)", "worlds", "track",
               axis="generated evaluation world (seed)", paper=False),
)

#: What ``rbc eval`` runs by default: the paper's eight (Table 9 as the paper has it).
PAPER_EXPERIMENTS: tuple[str, ...] = tuple(e.key for e in EXPERIMENTS if e.paper)
#: Unseen worlds per evaluation by default (``--worlds``).
DEFAULT_UNSEEN_WORLDS = 10


def run_eta(record: Mapping[str, Any]) -> float:
    """The eta of one run: the mean over its laps (0 for a run without a lap)."""
    laps = record["laps"]
    return statistics.fmean(lap["eta"] for lap in laps) if laps else 0.0


def experiment(key: str) -> Experiment:
    for exp in EXPERIMENTS:
        if exp.key == key:
            return exp
    raise KeyError(f"unknown experiment {key!r}; known: {', '.join(e.key for e in EXPERIMENTS)}")
