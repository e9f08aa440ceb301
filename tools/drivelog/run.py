"""One closed loop on a recording, assembled once: the driver, the car's wheelbase, the road, the loop.

``rbc drive-log``, ``rbc data crossval`` and ``rbc data road`` all build the loop here, so a recording is driven
(and its road found) the same way whichever command asks; the rules they pass are :class:`LoopRules`,
which check their own ranges.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol, TypedDict, TypeVar

import numpy as np

from tools.drivelog.drivers import make_driver
from tools.drivelog.loop import LoopResult, LoopRules, drive
from tools.drivelog.path import RecordedDrive
from tools.drivelog.road import RoadEdges, estimate_road
from tools.drivelog.rows import chosen_rows
from tools.drivelog.yaw import WheelbaseFit, wheelbase_or_default


class Bar(Protocol):
    """A progress callback ``bar(done, total)`` that ``close`` ends (:class:`tools.console.Progress`)."""

    def __call__(self, done: float, total: float) -> None: ...

    def close(self) -> None: ...


T = TypeVar("T")
#: Makes the progress bar of a phase (``"road"``: finding the road's edges, ``"loop"``: driving); None: no bars.
Bars = Callable[[str], Bar] | None


class MonitorOutcome(TypedDict):
    """The monitor on a drive: the take-overs it foresaw and how early (``foresight``), and what it saw."""

    takeovers_scored: int
    foreseen: int
    foreseen_1s: int
    leads_s: list[float | None]
    episodes: int  # warning episodes
    frames_scored: int


@dataclass(frozen=True)
class RecordingRun:
    """A closed loop on a recording and what it was driven with."""

    result: LoopResult
    driver: str  # the driver's name, for the record
    road: RoadEdges | None  # the road's edges in every frame (lane="road")
    wheelbase_fit: WheelbaseFit | None  # None: given, or the default where the frames could not say
    monitor: MonitorOutcome | None = None  # the model's misbehaviour monitor on the drive (monitor_outcome)


def monitor_outcome(log: RecordedDrive, result: LoopResult, readings: list[tuple[int, int]]) -> MonitorOutcome:
    """Which take-overs the monitor foresaw, and how early: the benchmark's rules on the recording's own clock
    (each take-over counts as leaving the road; ones right after another are left out as in the benchmark)."""
    from tools.monitoreval.scoring import DEFAULT_RULES, RunTrace, episodes, foresight

    clock = np.concatenate([[0.0], np.cumsum(np.maximum(log.dt, 0.0))])[:len(log)]
    t = np.array([clock[i] for i, _ in readings], dtype=np.float64)
    level = np.array([lv for _, lv in readings], dtype=np.uint8)
    takeovers = [(float(clock[k.frame]), "off_road") for k in result.takeovers]
    trace = RunTrace("drive-log", "real", t, level, takeovers, float(clock[-1]) if len(clock) else 0.0)
    found = foresight(trace, DEFAULT_RULES)
    return {"takeovers_scored": found["takeovers_scored"], "foreseen": found["foreseen"],
            "foreseen_1s": found["foreseen_1s"], "leads_s": found["leads_s"],
            "episodes": int(len(episodes(trace, DEFAULT_RULES))), "frames_scored": len(readings)}


def _with_bar(bars: Bars, phase: str, work: Callable[[Bar | None], T]) -> T:
    if bars is None:
        return work(None)
    bar = bars(phase)
    try:
        return work(bar)
    finally:
        bar.close()


def car_and_road(log: RecordedDrive, wheelbase_m: float | None = None, road: bool = True, bars: Bars = None,
                 say: Callable[[str], None] | None = None, track: str | None = None
                 ) -> tuple[float, WheelbaseFit | None, RoadEdges | None]:
    """The car's effective wheelbase (``wheelbase_m``, or fitted to the recorded frames: the default where the fit
    fails) and, with ``road``, the road's edges in every frame, found by ``track``'s profile (None: the track told
    from the asphalt's colour, :mod:`tools.drivelog.track`). ``say`` gets the fit and the road in a line each."""
    fit = None
    if wheelbase_m is None:
        wheelbase_m, fit = wheelbase_or_default(log)
        if fit is not None and say:
            say(f"car: effective wheelbase {fit.wheelbase_m:.2f} m, fitted on {fit.pairs} frame pairs "
                f"(image turn against recorded steering: r {fit.r:.2f})")
    edges = None
    if road:
        edges = _with_bar(bars, "road", lambda bar: estimate_road(log, wheelbase_m, on_frame=bar, track=track))
        if say:
            say(edges.describe())
    return wheelbase_m, fit, edges


def drive_recording(log: RecordedDrive, rules: LoopRules | None = None, model: Path | None = None,
                    baseline: str | None = None, steer_bias: float = 0.0, smooth: float | None = None,
                    wheelbase_m: float | None = None, snapshots: int = 8, bars: Bars = None,
                    say: Callable[[str], None] | None = None, track: str | None = None,
                    keep: np.ndarray | None = None, gain: float | None = None,
                    history_s: float = 0.0) -> RecordingRun:
    """Drive ``model`` (or a ``baseline``: ``recorded`` or ``zero``) along the recording by ``rules`` (None: the
    defaults, rbc drive-log's).

    The model's steering is multiplied and smoothed as drive_server would (``gain``, ``smooth``; None: as its
    metadata asks) and biased
    by ``steer_bias``; the wheelbase is ``wheelbase_m`` or fitted to the frames (``rules.wheelbase_m`` is
    replaced by it); the road is found only for ``lane="road"``, by ``track``'s profile (None: told from the
    frames). ``snapshots``: views kept for the strip; ``history_s``: the views of that many seconds before
    each take-over kept too. ``keep`` (a flag per frame): drive only those frames, each
    stretch of them from the recorded path (:mod:`tools.drivelog.rows`); the road and the wheelbase are still
    found on the whole recording.
    """
    rules = rules or LoopRules()
    driven = log if keep is None else chosen_rows(log, None, keep)[0]
    readings: list[tuple[int, int]] = []
    driver, name = make_driver(driven, model, baseline, steer_bias, smooth, readings, gain)
    wheelbase, fit, road = car_and_road(log, wheelbase_m, rules.lane == "road", bars, say, track)
    if keep is not None:
        road = chosen_rows(log, road, keep)[1]
    rules = replace(rules, wheelbase_m=wheelbase)
    log = driven

    def loop(bar: Bar | None) -> LoopResult:
        on_step = None if bar is None else (lambda j: bar(j + 1, len(log)))
        return drive(log, driver, rules, snapshots=snapshots, on_step=on_step, road=road, history_s=history_s)

    result = _with_bar(bars, "loop", loop)
    return RecordingRun(result, name, road, fit, monitor_outcome(log, result, readings) if readings else None)
