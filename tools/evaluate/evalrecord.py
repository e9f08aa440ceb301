"""An evaluation's record, ``DIR/results.json`` (``rbc eval --out DIR``): the one module that names the file, writes it
and reads it back typed, for ``rbc compare`` and anyone else who reads an evaluation, so none spells its name or its
keys again; and its runs' records (:class:`EvalRun`, :class:`Retry`), apart from the runner that drives them so that
what reads them need not import it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Required, TypedDict

from protocol.errors import BadValue, UserError
from protocol.runrecords import read_json, write_json
from tools.sim.driving.scenario import RunResultRecord

if TYPE_CHECKING:
    from tools.evaluate.experiments import AxisValue

RESULTS = "results.json"


class EvalRun(RunResultRecord, total=False):
    """One run of an evaluation as the journal and ``results.json`` hold it: the task, then the run's record
    (:class:`~tools.sim.driving.scenario.RunResultRecord`), then whether it was autonomous, the monitor's figures
    (``--monitor``) and the trajectory map of a run that was not autonomous."""

    experiment: Required[str]
    behavior: Required[str]
    value: Required[AxisValue]
    seed: Required[int]
    scenario: Required[dict[str, object]]  # the ScenarioConfig keyword arguments (the task's key)
    autonomous: bool
    monitor: dict[str, object]
    map: str


class Retry(TypedDict):
    """A run a backend retried after a failure (``meta.retried`` of ``results.json``)."""

    experiment: str
    value: AxisValue
    seed: int
    attempt: int
    error: str


class NoEvaluationError(UserError):
    """A folder that holds no evaluation's record."""

    hint = "run rbc eval --out DIR first"


@dataclass(frozen=True)
class EvalRecord:
    """What ``rbc eval`` recorded: ``meta`` (which model, driver, suite and code; how it ran), ``summary`` (per
    experiment: its measure and figures, Table 9's cells) and ``runs`` (every finished run)."""

    eval_dir: Path
    meta: Mapping[str, object]
    summary: Mapping[str, Any] = field(default_factory=dict)
    runs: Sequence[EvalRun] = ()

    @staticmethod
    def path(eval_dir: str | Path) -> Path:
        return Path(eval_dir) / RESULTS

    @classmethod
    def load(cls, eval_dir: str | Path) -> EvalRecord:
        """The evaluation in ``eval_dir``; :class:`NoEvaluationError` when it holds none, BadValue when it is not
        one."""
        path = cls.path(eval_dir)
        if not path.is_file():
            raise NoEvaluationError(f"{eval_dir} has no {RESULTS}", f"run rbc eval --out {eval_dir} first")
        return cls.from_dict(read_json(path), eval_dir)

    @classmethod
    def from_dict(cls, record: object, eval_dir: str | Path = ".") -> EvalRecord:
        """A record as ``rbc eval`` writes it (an older one may lack a summary or runs)."""
        where = cls.path(eval_dir)
        if not isinstance(record, dict) or not isinstance(record.get("meta"), dict):
            raise BadValue(f"{where}: not an evaluation's record (no meta object)")
        summary, runs = record.get("summary") or {}, record.get("runs") or []
        if not isinstance(summary, dict) or not isinstance(runs, list):
            raise BadValue(f"{where}: not an evaluation's record (its summary or runs are of the wrong kind)")
        return cls(Path(eval_dir), record["meta"], summary, runs)

    def write(self) -> Path:
        """Write the record (atomically) to its folder's file; returns the file."""
        path = self.path(self.eval_dir)
        write_json(path, {"meta": dict(self.meta), "summary": dict(self.summary), "runs": list(self.runs)})
        return path

    def _meta(self, key: str) -> object:
        if key not in self.meta:
            raise BadValue(f"{self.path(self.eval_dir)}: its meta has no {key!r} (written by another version)",
                           "evaluate the model again")
        return self.meta[key]

    @property
    def behavior(self) -> str:
        return str(self._meta("behavior"))

    @property
    def model(self) -> Path:
        """The model file as given to ``rbc eval``."""
        return Path(str(self._meta("model")))

    @property
    def model_resolved(self) -> Path:
        """The model file's absolute path when it was evaluated (the given one in a record that predates it)."""
        return Path(str(self.meta.get("model_resolved", self._meta("model"))))

    @property
    def model_sha256(self) -> str:
        return str(self._meta("model_sha256"))
