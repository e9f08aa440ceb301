"""Files of a training run (config, history, checkpoint, model), written through the atomic writers
of :mod:`drive_server.runrecords`, so a crash or Ctrl-C never leaves half a file behind."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from drive_server.runrecords import write_text

CONFIG = "config.json"
HISTORY = "history.csv"
CHECKPOINT = "checkpoint.pt"
MODEL = "model.onnx"
HISTORY_FIELDS = ("epoch", "train_loss", "val_loss", "seconds")


def write_history(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=HISTORY_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: r[k] for k in HISTORY_FIELDS})
    write_text(path, buf.getvalue())


def read_history(path: Path) -> list[dict[str, float]]:
    with Path(path).open(newline="", encoding="utf-8") as fh:
        return [{k: (int(v) if k == "epoch" else float(v)) for k, v in row.items()} for row in csv.DictReader(fh)]
