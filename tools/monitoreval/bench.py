"""``rbc monitor eval``'s work: drive the run set, score the monitor, compare ``act`` with ``warn``, time it, and
write the record (seed, plan, code version) and its tables, each through a temporary file."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from protocol.errors import BadValue
from protocol.runrecords import code_version, write_json, write_text
from tools.monitoreval.runset import RunSpec, failing_runs, nominal_runs, undertrained_runs
from tools.monitoreval.scoring import ScoringRules

RECORD = "monitor_eval.json"
TABLES = "monitor_eval.md"


@dataclass(frozen=True)
class EvalPlan:
    """What to measure; the defaults are defined here once (``rbc monitor eval``'s flags read them)."""

    model: Path
    out: Path
    nominal: int = 90  # held-out nominal runs of one lap (about 2 min each: 3 h)
    per_setting: int = 8  # runs of each perturbation intensity and each degraded model (about 430 misbehaviours)
    act: bool = True  # also drive every run with --monitor act
    cost_log: Path | None = None  # recorded frames to time the server's pipeline on
    workers: int = 1  # processes driving runs side by side
    shadows: tuple[Path, ...] = ()  # other monitors (files of the same steering model) scored on the same drives
    # steering models of the served model's recipe stopped early, each driven with the served model's monitor
    undertrained: tuple[Path, ...] = ()
    rescore: bool = False  # score the journal's runs again without driving (whatever code drove them)
    rules: ScoringRules = field(default_factory=ScoringRules)

    def specs(self) -> list[RunSpec]:
        return nominal_runs(self.nominal) + failing_runs(self.per_setting) + undertrained_runs(
            [(path.stem, digest, epochs) for path, digest, epochs in self.checkpoints()], self.per_setting)

    def checkpoints(self) -> list[tuple[Path, str, float]]:
        """Each under-trained checkpoint with its content digest and the epochs it was trained."""
        from tools.monitoreval.modelfiles import checkpoint_epochs, file_digest

        return [(c, file_digest(c), checkpoint_epochs(c)) for c in self.undertrained]

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: str(v) if isinstance(v, Path) else [str(x) for x in v] if k in ("shadows", "undertrained") else v
                for k, v in d.items()}


def evaluate(plan: EvalPlan, progress: Callable[[int, int, str], None] | None = None) -> dict[str, Any]:
    from drive_server.serving.model import SteeringModel
    from tools.monitoreval.cost import monitor_cost
    from tools.monitoreval.insample import in_sample, markdown
    from tools.monitoreval.modelfiles import check_checkpoint, file_digest
    from tools.monitoreval.report import closed_loop, compare, figures, sweep, table_rows, tables
    from tools.monitoreval.runner import drive_all

    found = SteeringModel(plan.model).monitor()
    if found is None:
        raise BadValue(f"{plan.model.name} carries no monitor (attach one with rbc monitor fit)")
    spec = found[0]
    modes = ("warn", "act") if plan.act else ("warn",)
    shadow_specs = {}
    for path in plan.shadows:
        other = SteeringModel(path).monitor()
        if other is None:
            raise BadValue(f"{path.name} carries no monitor")
        shadow_specs[path.name] = other[0]
    checkpoints = plan.checkpoints()
    seen: dict[str, Path] = {}
    for path, digest, _ in checkpoints:
        if digest in seen:
            raise BadValue(f"checkpoint {path}: the same file as {seen[digest]}")
        seen[digest] = path
        check_checkpoint(plan.model, path)
    results = drive_all(plan.specs(), plan.model, modes, plan.out, progress, plan.workers, plan.shadows,
                        plan.rescore, plan.undertrained)
    record: dict[str, Any] = {
        "model": plan.model.name, "model_sha256": file_digest(plan.model),
        "monitor": {"score": spec.score, "warn": spec.warn, "alarm": spec.alarm, "window": spec.window,
                    "calibration": spec.calibration},
        "plan": plan.to_dict(), "code_version": code_version(),
        "drive_code": sorted({json.loads(k)["code"] for k in _journal_keys(plan.out)}),
        "runs": {"total": len(results), "nominal": plan.nominal, "per_setting": plan.per_setting},
        "undertrained": [{"file": path.name, "sha256": digest, "epochs": epochs}
                         for path, digest, epochs in checkpoints],
        "figures": figures(results, plan.rules),
        "closed_loop": closed_loop(results) if plan.act else {},
        "monitors": compare(results, plan.rules, shadow_specs, f"{spec.score} (drives the car)",
                            {n: m.score for n, m in shadow_specs.items()}),
        "sweep": sweep(results, plan.rules, {None: (spec.score, spec),
                                             **{n: (m.score, m) for n, m in shadow_specs.items()}}),
        "in_sample": in_sample(results, plan.rules, {None: (spec.score, spec.window),
                                                     **{n: (m.score, m.window) for n, m in shadow_specs.items()}}),
        "shadow_specs": {n: {"score": m.score, "warn": m.warn, "alarm": m.alarm, "window": m.window,
                             "calibration": m.calibration} for n, m in shadow_specs.items()},
        "cost": monitor_cost(plan.model, plan.cost_log) if plan.cost_log is not None else None,
    }
    record["rows"] = table_rows(record)
    write_json(plan.out / RECORD, record)
    write_text(plan.out / TABLES, tables(record) + markdown(record))
    return record


def _journal_keys(out: Path) -> list[str]:
    """The keys of the runs in ``out``'s journal (the versions of the code that drove them)."""
    from tools.monitoreval.runner import JOURNAL, Journal

    return list(Journal(out / JOURNAL).done)
