"""Which camera a recording's frames were taken with: ``camera_rig.json`` beside its driving log.

``rbc collect`` writes it (the headless simulator has two camera rigs, ``classic`` and ``unity``);
``rbc train`` reads it for every ``--data`` folder and stamps the one rig of its data into the model, so
the headless simulator later shows a model the camera it learnt from. A folder without the file is a
recording of the real simulator (or of drive_server serving it): Unity's own camera, ``unity``.
The headless simulator also records which of its named tracks the laps were driven on (``track``), so that
``rbc drive-log`` finds the road by that track's look instead of guessing it from the asphalt's colour.
Stdlib only.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable
from pathlib import Path

from protocol.datalog import LOG_NAMES

log = logging.getLogger(__name__)

RIG_FILE = "camera_rig.json"
#: The rig of frames recorded without a rig file: the real simulator's camera.
REAL_RIG = "unity"
#: What a folder of frames from more than one rig, or data of several rigs, records.
MIXED = ""


def _folder(data: Path | str) -> Path:
    data = Path(data)
    return data.parent if data.suffix.lower() == ".csv" else data


def _read(data: Path | str) -> dict[str, object] | None:
    """The rig file's fields; None without one (or unreadable, said once)."""
    path = _folder(data) / RIG_FILE
    try:
        fields = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        log.warning("%s: unreadable, taking the frames for the real simulator's camera", path)
        return None
    return fields if isinstance(fields, dict) else None


def read_rig(data: Path | str) -> str:
    """The rig of the recording in ``data`` (a folder, or its log file); :data:`REAL_RIG` without a rig file."""
    value = (_read(data) or {}).get("rig", REAL_RIG)
    return value if isinstance(value, str) else REAL_RIG


def read_track(data: Path | str) -> str | None:
    """The named track the recording in ``data`` was driven on, where the rig file says it (headless laps of
    one track); None otherwise (real recordings, generated worlds, laps of several tracks)."""
    value = (_read(data) or {}).get("track")
    return value if isinstance(value, str) and value else None


def write_rig(folder: Path, rig: str, append: bool = False, track: str | None = None) -> None:
    """Record ``rig`` (and the named ``track``, if one) for the frames in ``folder``; appending frames of
    another rig records :data:`MIXED`, of another track no track."""
    folder = Path(folder)
    earlier = (folder / RIG_FILE).is_file() or any((folder / name).is_file() for name in LOG_NAMES)
    if append and earlier:
        if read_rig(folder) != rig:  # a real recording has no rig file: unity
            rig = MIXED
        if read_track(folder) != track:
            track = None
    folder.mkdir(parents=True, exist_ok=True)
    fields: dict[str, str] = {"rig": rig} | ({"track": track} if track else {})
    tmp = folder / (RIG_FILE + ".tmp")
    tmp.write_text(json.dumps(fields) + "\n", encoding="utf-8")
    tmp.replace(folder / RIG_FILE)


def data_rig(sources: Iterable[Path | str]) -> str:
    """The one rig of all ``sources``, or :data:`MIXED` when they differ."""
    rigs = {read_rig(s) for s in sources}
    return rigs.pop() if len(rigs) == 1 else MIXED
