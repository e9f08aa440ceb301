"""Cross-validation by driver: every public recording scored by the model its fold was held out of.

The manifest puts each recording in a fold (one driver's recordings share one); a model trained on the
other folds scores it open loop (every row, centre camera, against the recorded steering and against
always-0) and closed loop (``rbc drive-log``, on every track of :data:`CLOSED_LOOP_TRACKS`). What a new
driver's data looks like to the recipe, as one table: the README's and the model card's figures come from here.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from protocol.codeversion import ROOT, code_digest, data_digest
from tools.realdata.recordings import PublicRecording
from tools.sim.driving.rules import TARGET_ETA

if TYPE_CHECKING:
    from tools.drivelog.loop import LoopRules

log = logging.getLogger(__name__)
#: The placeholder of ``--models`` that becomes each recording's fold.
FOLD_FIELD = "{fold}"
#: Tracks whose recordings are also driven closed loop: all three. The road is found by the manifest's track's
#: profile (tools.drivelog.track: the jungle's two lanes and shade, the mountain's dark road), and on the jungle's
#: and the mountain's hills the ground ahead is seen at the pitch the side cameras measure in every frame
#: (tools.drivelog.pitch), where over flat ground its views and edges were wrong.
CLOSED_LOOP_TRACKS = ("lake", "jungle", "mountain")


@dataclass(frozen=True)
class RecordingScore:
    """One recording under one model. ``eta`` and the take-over figures are None where not driven."""

    name: str
    track: str
    fold: str
    model: str
    frames: int
    zero_mse: float
    mse: float
    pearson_r: float
    eta: float | None = None
    interventions: int | None = None
    seconds_per_takeover: float | None = None
    # against the recorded steering's INTENT_FRAMES average (what the driver meant), and that average's r
    # with the recorded steering: about the most r any picture-to-steering model reaches here
    r_to_intent: float | None = None
    intent_r: float | None = None
    smooth: float = 1.0  # the model's steering smoothed as drive_server does (drive_server.serving.smoothing; 1: not)
    off_road_s: float | None = None  # closed loop: log time the recorded driver was off the road (not counted)
    reversing_s: float | None = None  # closed loop: log time the recorded driver reversed (not counted)

    @property
    def beats_zero(self) -> bool:
        return self.mse < self.zero_mse

    def as_dict(self) -> dict[str, object]:
        return asdict(self) | {"beats_zero": self.beats_zero}


@dataclass(frozen=True)
class TrackSummary:
    track: str
    recordings: int
    mean_r: float
    beats_zero: int
    mean_eta: float | None
    seconds_per_takeover: float | None  # the track's driving seconds over its take-overs; None: none
    mean_r_to_intent: float | None = None
    mean_intent_r: float | None = None
    worst_eta: float | None = None  # the targets are per recording: every one at TARGET_ETA or more
    at_least_95: int | None = None
    takeovers: int | None = None


def model_for(pattern: str, rec: PublicRecording) -> Path:
    """The model that never saw ``rec``: ``pattern`` with ``{fold}`` replaced (a pattern without it: one model)."""
    return Path(pattern.replace(FOLD_FIELD, rec.fold))


def score_recording(rec: PublicRecording, root: Path, model: Path, closed_loop: bool = True,
                    rules: LoopRules | None = None, smooth: float | None = None) -> RecordingScore:
    """Open loop on every row; closed loop too on the tracks of :data:`CLOSED_LOOP_TRACKS`; in both the model's
    steering smoothed as drive_server would (``smooth``; None: as the model's metadata asks); the closed loop
    by ``rules`` (None: rbc drive-log's defaults), the wheelbase fitted to the recording as rbc drive-log does."""
    from tools.evaluate.offline import score_models
    from tools.realdata.stats import INTENT_FRAMES

    data = root / rec.name
    (score,) = score_models([model], data, smooth_frames=INTENT_FRAMES, smooth=smooth)
    eta = interventions = per_takeover = off_road = reversed_s = None
    if closed_loop and rec.track in CLOSED_LOOP_TRACKS:
        eta, interventions, per_takeover, off_road, reversed_s = _closed_loop(data, model, rules, smooth, rec.track)
    return RecordingScore(rec.name, rec.track, rec.fold, str(model), score.frames, round(score.zero_mse, 5),
                          round(score.mse, 5), round(score.pearson_r, 4), eta, interventions, per_takeover,
                          _rounded(score.pearson_r_smoothed), _rounded(score.intent_r), score.smooth, off_road,
                          reversed_s)


def _rounded(value: float | None) -> float | None:
    return None if value is None or np.isnan(value) else round(value, 4)


def _closed_loop(data: Path, model: Path, rules: LoopRules | None, smooth: float | None,
                 track: str | None = None) -> tuple[float, int, float, float, float]:
    """eta, take-overs, seconds driven per take-over, and seconds the recorded driver was off the road and
    reversing; the road found by ``track``'s profile (None: told from the frames)."""
    from protocol.datalog import read_log
    from tools.drivelog.path import recorded_drive
    from tools.drivelog.run import drive_recording

    log = recorded_drive(read_log(data)[0])
    result = drive_recording(log, rules, model, smooth=smooth, snapshots=0, track=track).result  # as rbc drive-log
    return (round(result.eta, 2), result.interventions, round(result.driving_time_s / max(1, result.interventions), 2),
            round(result.off_road_s, 2), round(result.reversing_s, 2))


def score_all(recs: Sequence[PublicRecording], root: Path, pattern: str, closed_loop: bool = True,
              rules: LoopRules | None = None, workers: int = 1,
              on_done: Callable[[int, int], None] | None = None, smooth: float | None = None,
              journal: ScoreJournal | None = None, what: str = "folds") -> list[RecordingScore]:
    """Every recording under its fold's model, in ``recs`` order; ``workers`` processes at once. With a
    ``journal``, a recording already scored under the same key is taken from it and each new score is added
    to it as soon as it is finished (a stopped run resumes there)."""
    jobs = [(rec, root, model_for(pattern, rec), closed_loop, rules, smooth) for rec in recs]
    code = measure_version() if journal is not None else ""
    keys = [score_key(what, rec.name, model, closed_loop, rules, smooth, code,
                      data_digest([root / rec.name]) if journal is not None else "")
            for rec, _, model, *_ in jobs]
    out: list[RecordingScore | None] = [journal.get(k) if journal else None for k in keys]
    todo = [i for i, s in enumerate(out) if s is None]
    finished = len(jobs) - len(todo)

    def done(i: int, score: RecordingScore) -> None:
        nonlocal finished
        out[i] = score
        if journal is not None:
            journal.add(keys[i], score)
        finished += 1
        if on_done:
            on_done(finished, len(jobs))

    if on_done:
        on_done(finished, len(jobs))
    if workers <= 1 or len(todo) <= 1:
        for i in todo:
            done(i, score_recording(*jobs[i]))
        return [r for r in out if r is not None]
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(score_recording, *jobs[i]): i for i in todo}
        for future in as_completed(futures):
            done(futures[future], future.result())
    return [r for r in out if r is not None]


def summarise(scores: Sequence[RecordingScore]) -> list[TrackSummary]:
    """Per track, in the order tracks first appear: mean r, how many beat always-0, mean eta where driven."""
    tracks = list(dict.fromkeys(s.track for s in scores))
    out = []
    for track in tracks:
        mine = [s for s in scores if s.track == track]
        driven = [s for s in mine if s.eta is not None]
        etas = [s.eta for s in driven if s.eta is not None]  # the same rows, typed for the checker
        out.append(TrackSummary(
            track, len(mine), round(float(np.mean([s.pearson_r for s in mine])), 3), sum(s.beats_zero for s in mine),
            round(float(np.mean([s.eta for s in driven])), 2) if driven else None,
            _pooled_seconds_per_takeover(driven),
            _mean_of([s.r_to_intent for s in mine]), _mean_of([s.intent_r for s in mine]),
            float(min(etas)) if driven else None,
            int(sum(eta >= TARGET_ETA for eta in etas)) if driven else None,
            int(sum(s.interventions or 0 for s in driven)) if driven else None))
    return out


def _pooled_seconds_per_takeover(driven: Sequence[RecordingScore]) -> float | None:
    """Seconds driven per take-over over all of a track's driven recordings; None without a take-over (a
    recording without one has no rate of its own, and averaging its driving time in would make one up)."""
    takeovers = sum(s.interventions or 0 for s in driven)
    if not takeovers:
        return None
    seconds = sum((s.seconds_per_takeover or 0.0) * max(1, s.interventions or 0) for s in driven)
    return round(seconds / takeovers, 2)


def _mean_of(values: Sequence[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return round(float(np.mean(known)), 3) if known else None


# --------------------------------------------------------------------------- a cross-validation that survives a stop
# Every finished recording's score is appended (and flushed) to a journal the moment it is finished, keyed by
# everything that determines it: the recording and its data, the model file's content (a retrained fold model is
# scored afresh), the closed-loop rules, the smoothing and the code that scores (derived from what it imports:
# protocol.codeversion). A run started again with the same journal skips what is in it; every score depends only
# on its key, so a resumed run gives the clean run's figures. A line that no longer loads (torn by a kill, or
# keyed in an older format) is counted in one warning, and that recording scored again.

#: Beside the JSON record: ``OUT.json`` keeps its journal in ``OUT.journal.jsonl``.
SUFFIX = ".journal.jsonl"


def journal_for(json_path: Path) -> Path:
    return json_path.with_name(json_path.stem + SUFFIX)


def model_digest(path: Path) -> str:
    """The model file's content, so the same path holding a retrained model is not taken for the old one."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


#: Where the scoring starts: a recording's score depends on the code this module runs (score_recording's
#: imports: the offline scorer, the labels, the metrics, the closed loop, the server's pipeline, ...), found by
#: following the imports, so a change to any of it, and to nothing else, scores every recording afresh.
MEASURE_ENTRY = __name__
CODE_ROOT = ROOT
#: The fields of a key; a journal line keyed otherwise (an older format) is not taken.
KEY_FIELDS = frozenset({"what", "recording", "data", "model", "closed_loop", "rules", "smooth", "code"})


def measure_version(root: Path | None = None) -> str:
    """The version of the scoring code under ``root`` (None: :data:`CODE_ROOT`): :data:`MEASURE_ENTRY` and all
    it imports."""
    return code_digest(MEASURE_ENTRY, root=root or CODE_ROOT)


def score_key(what: str, name: str, model: Path, closed_loop: bool, rules: LoopRules | None, smooth: float | None,
              code: str = "", data: str = "") -> str:
    """Everything a recording's score depends on, as one canonical string: with ``code`` (the code version)
    a run resumed after the measure's code changed scores every recording afresh instead of mixing two, with
    ``data`` (the recording's :func:`~protocol.codeversion.data_digest`) a recording cut or fetched again too."""
    return json.dumps({"what": what, "recording": name, "data": data, "model": model_digest(model),
                       "closed_loop": closed_loop, "rules": asdict(rules) if rules is not None else None,
                       "smooth": smooth, "code": code}, sort_keys=True)


class ScoreJournal:
    """Finished scores by key, read from ``path`` at start and appended to as recordings finish."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.scores: dict[str, RecordingScore] = {}
        self._torn = False  # the file ends inside a line (a kill mid-write): the next entry starts a new one
        if path is None or not path.exists():
            return
        names = {f.name for f in fields(RecordingScore)}
        text = path.read_text(encoding="utf-8")
        self._torn = bool(text) and not text.endswith("\n")
        skipped = 0
        for line in text.splitlines():
            if not line.strip():
                continue
            try:
                entry = json.loads(line)
                if set(json.loads(entry["key"])) != KEY_FIELDS:
                    raise ValueError("a key of another format")
                self.scores[entry["key"]] = RecordingScore(**{k: v for k, v in entry["score"].items() if k in names})
            except (ValueError, KeyError, TypeError, AttributeError):  # torn by a kill, or an older format
                skipped += 1
        if skipped:
            log.warning("%s: %d line(s) no longer load (torn by a stop, or written by an older version); "
                        "those recordings are scored again", path, skipped)

    def get(self, key: str) -> RecordingScore | None:
        return self.scores.get(key)

    def add(self, key: str, score: RecordingScore) -> None:
        self.scores[key] = score
        if self.path is None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a", encoding="utf-8") as fh:
            fh.write(("\n" if self._torn else "") + json.dumps({"key": key, "score": score.as_dict()}) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        self._torn = False
