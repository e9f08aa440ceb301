"""A training run's folder: the one module that names its files (config, history, checkpoint, model), reads them
into a typed :class:`RunRecord` and writes them through the atomic writers of :mod:`protocol.runrecords`, so a
crash or Ctrl-C never leaves half a file behind and no other module spells a file name or a record's keys again."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TypedDict, cast

from protocol.errors import BadValue, UserError
from protocol.runrecords import write_json, write_text

CONFIG = "config.json"
HISTORY = "history.csv"
CHECKPOINT = "checkpoint.pt"
MODEL = "model.onnx"
LOSS_PLOT = "loss.png"  # the loss per epoch (rbc train in the run folder, rbc inspect in RUN/inspect/)
HISTORY_FIELDS = ("epoch", "train_loss", "val_loss", "seconds")


class NotARunError(UserError):
    """A folder that holds no training run's record (or one that is not JSON of the right shape)."""

    hint = "give the folder rbc train --out wrote"


@dataclass(frozen=True)
class EpochRow:
    """One line of ``history.csv``: an epoch's mean training loss, validation loss and wall seconds."""

    epoch: int
    train_loss: float
    val_loss: float
    seconds: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class RunPaths:
    """Where a run's files lie (whether or not they are there yet)."""

    run_dir: Path

    @property
    def config(self) -> Path:
        return self.run_dir / CONFIG

    @property
    def history(self) -> Path:
        return self.run_dir / HISTORY

    @property
    def checkpoint(self) -> Path:
        return self.run_dir / CHECKPOINT

    @property
    def model(self) -> Path:
        return self.run_dir / MODEL

    @property
    def loss_plot(self) -> Path:
        return self.run_dir / LOSS_PLOT


class SplitRecord(TypedDict):
    """How a run divided its samples (``models.data.split.SplitSpec``, its kind by name)."""

    kind: str
    val_fraction: float
    block_frames: int
    gap_frames: int


class Resolved(TypedDict, total=False):
    """The schedule and sample counts a run's configuration resolved to."""

    epochs: int
    steps_per_epoch: int
    validation_steps: int
    deletion_rate: float
    optimizer: str
    loss: str
    train_samples: int
    val_samples: int
    zero_steer_train_samples: int
    split: SplitRecord


class LogEntry(TypedDict):
    """One recording's log as training read it."""

    path: str
    rows: int
    samples: int
    skipped: int


class ExportResult(TypedDict, total=False):
    """What the export added to a run's record."""

    export: str  # which epoch is exported: "best" or "last"
    exported_epoch: int
    val_mse: float
    last_epoch_val_mse: float
    val_metrics: dict[str, float]
    split: str
    rows: dict[str, int]
    onnx_max_diff: float
    val_by_recording: list[dict[str, object]]  # each recording's log and its metrics


class ConfigRecord(TypedDict, total=False):
    """``config.json`` as training writes it (a record of an older run may lack some keys)."""

    config: dict[str, Any]  # the run's TrainConfig as stored, read back by TrainConfig.from_dict (older keys too)
    recipe: dict[str, dict[str, object]]  # the same settings, resolved, as a recipe file holds them
    resolved: Resolved
    rows: dict[str, int]
    augment: dict[str, object]  # the augmentation's settings
    contract: dict[str, Any]  # the preprocessing contract's fields (of the run's version)
    logs: list[LogEntry]
    unreadable_frames: int
    code_version: str
    torch: str  # its version
    created: str  # when, ISO 8601 with the zone
    world_size: int  # training processes (DDP)
    result: ExportResult  # added after the export


@dataclass(frozen=True)
class RunRecord:
    """What a training run recorded: its configuration record (what ``rbc train`` wrote before training and the
    result it added after the export) and its per-epoch history. ``record`` is the whole record as written; the
    properties name its parts, so no reader spells a key of it."""

    run_dir: Path
    record: ConfigRecord
    history: tuple[EpochRow, ...] = field(default=())

    @classmethod
    def load(cls, run_dir: str | Path) -> RunRecord:
        """The run in ``run_dir``; :class:`NotARunError` when it holds no run's record."""
        paths = RunPaths(Path(run_dir))
        if not paths.config.is_file():
            raise NotARunError(f"{paths.run_dir}: not a training run folder (no {CONFIG})")
        try:
            record = json.loads(paths.config.read_text(encoding="utf-8"))
        except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError
            raise NotARunError(f"{paths.config}: not a training run's config (not JSON: {exc})") from None
        history = read_history(paths.history) if paths.history.is_file() else []
        return cls.from_dict(record, paths.run_dir, history)

    @classmethod
    def from_dict(cls, record: object, run_dir: str | Path = ".", history: Iterable[EpochRow] = ()) -> RunRecord:
        """A record as training writes it (``config`` an object); :class:`NotARunError` for anything else."""
        where = Path(run_dir) / CONFIG
        if not isinstance(record, dict):
            raise NotARunError(f"{where}: not a training run's config (a JSON {type(record).__name__})")
        if not isinstance(record.get("config"), dict):
            raise NotARunError(f"{where}: not a training run's config (its config is no JSON object)")
        return cls(Path(run_dir), cast(ConfigRecord, record), tuple(history))  # a JSON object with a config object

    @property
    def paths(self) -> RunPaths:
        return RunPaths(self.run_dir)

    @property
    def config_path(self) -> Path:
        return self.paths.config

    @property
    def model_path(self) -> Path:
        return self.paths.model

    @property
    def checkpoint_path(self) -> Path:
        return self.paths.checkpoint

    @property
    def config(self) -> dict[str, Any]:
        """The run's configuration as stored (``TrainConfig.from_dict`` reads it back)."""
        return dict(self.record["config"])

    @property
    def resolved(self) -> Resolved:
        """The schedule and sample counts the configuration resolved to."""
        found = self.record.get("resolved")
        return found.copy() if found else {}

    @property
    def recipe(self) -> dict[str, dict[str, object]] | None:
        """The resolved recipe (None in a record written before records held it)."""
        return self.record.get("recipe")

    @property
    def rows(self) -> dict[str, int]:
        return dict(self.record.get("rows") or {})

    @property
    def logs(self) -> list[LogEntry]:
        return list(self.record.get("logs") or [])

    @property
    def contract(self) -> dict[str, Any]:
        return dict(self.record.get("contract") or {})

    @property
    def result(self) -> ExportResult | None:
        """What the export added (exported epoch, validation metrics ...); None until the run exported."""
        return self.record.get("result")

    @property
    def finished(self) -> bool:
        """Whether the run exported its model: the record holds its result and the model file is there."""
        return self.result is not None and self.model_path.is_file()

    @property
    def last_epoch(self) -> EpochRow | None:
        return self.history[-1] if self.history else None


def write_config(run_dir: Path, record: Mapping[str, object]) -> None:
    """Write the run's configuration record (before training)."""
    write_json(RunPaths(Path(run_dir)).config, dict(record))


def write_result(run_dir: Path, result: Mapping[str, object]) -> None:
    """Add what the export found to the run's record."""
    run = RunRecord.load(run_dir)
    write_config(run.run_dir, {**run.record, "result": dict(result)})


def write_history(run_dir: Path, rows: Iterable[EpochRow | Mapping[str, object]]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=HISTORY_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        row = r.as_dict() if isinstance(r, EpochRow) else r
        w.writerow({k: row[k] for k in HISTORY_FIELDS})
    write_text(RunPaths(Path(run_dir)).history, buf.getvalue())


def read_history(path: Path) -> list[EpochRow]:
    """The rows of a ``history.csv`` (read as CSV: quoted fields and columns beyond the four are fine);
    :class:`~protocol.errors.BadValue` naming the file and line for a row that is not one."""
    with Path(path).open(newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        missing = [k for k in HISTORY_FIELDS if k not in (reader.fieldnames or ())]
        if missing:
            raise BadValue(f"{path}: not a training history (no column {', '.join(missing)})")
        out = []
        for row in reader:
            try:
                out.append(EpochRow(int(float(row["epoch"])), float(row["train_loss"]), float(row["val_loss"]),
                                    float(row["seconds"])))
            except (TypeError, ValueError) as exc:
                raise BadValue(f"{path}: line {reader.line_num}: not an epoch's row ({exc})") from None
        return out
