"""``rbc data crossval`` as one call: the plan's recordings scored fold by fold (each fold's model trained first
with a recipe), the JSON written after each finished fold, the tables printed and the plot drawn.

The scoring itself is :mod:`tools.realdata.crossval`; this module only puts it in order and refuses bad input
before hours of work.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from tools.drivelog.loop import LoopRules
from tools.errors import CommandError
from tools.realdata.crossval import RecordingScore
from tools.realdata.recordings import PublicRecording


@dataclass(frozen=True)
class CrossvalPlan:
    """What one cross-validation scores and where it writes; ``rbc data crossval``'s defaults are these fields."""

    root: Path = Path("real")  # where rbc data fetch put the recordings
    models: str | None = None  # the fold models, {fold} for the fold's letter (None: --recipe's runs)
    recipe: str | None = None  # train the fold models with this rbc train recipe first, into runs
    runs: Path = Path("runs/crossval")  # with a recipe: where the fold runs live, runs/fold-F
    peer: str | None = None  # also score this model (trained elsewhere) on every recording
    track: str | None = None  # only the recordings of this track (None: every track)
    names: tuple[str, ...] | None = None  # only these recordings (None: all)
    closed_loop: bool = True  # also drive each recording closed loop (rbc drive-log)
    rules: LoopRules = field(default_factory=LoopRules)  # when a person takes over in the closed loop
    smooth: float | None = None  # the fold models' steering smoothing (None: the model's own)
    workers: int = 2  # recordings scored at once
    json_out: Path | None = None  # every score as JSON, after each finished fold (and its journal beside it)
    plot: Path | None = None  # each recording's closed-loop degree of autonomy, per track


def run_crossval(plan: CrossvalPlan) -> int:
    """Score every recording of ``plan``; 0, or 130 when a stop interrupted a fold's training (the same plan run
    again continues it). Bad input is a CommandError before any work."""
    from protocol.runrecords import write_json
    from tools.console import Progress
    from tools.realdata.crossval import ScoreJournal, journal_for, model_for, score_all
    from tools.realdata.crossval_tables import format_tables
    from tools.realdata.foldtrain import train_fold
    from tools.realdata.recordings import public_recordings, require_fetched, select

    every = public_recordings()
    recs = select(every, plan.track, plan.names)
    if not recs:
        raise CommandError("no public recording among those named")
    if not 1 <= plan.workers <= 64:
        raise CommandError("--workers must be 1..64")
    pattern = _check_models(plan, every, recs)
    require_fetched(recs, plan.root)
    journal = ScoreJournal(journal_for(plan.json_out) if plan.json_out else None)
    runs = [("folds", pattern)] + ([("peer", plan.peer)] if plan.peer else [])
    results: dict[str, list[RecordingScore]] = {what: [] for what, _ in runs}
    order = {r.name: i for i, r in enumerate(recs)}
    folds = sorted({r.fold for r in recs})
    for n, fold in enumerate(folds, start=1):
        mine = [r for r in recs if r.fold == fold]
        if plan.recipe:
            print(f"fold {fold} ({n} of {len(folds)}): model {model_for(pattern, mine[0])}", flush=True)
            if train_fold(plan.recipe, fold, every, plan.root, plan.runs) is None:
                print(f"interrupted while training fold {fold}; the same command continues it", flush=True)
                return 130
        for what, models in runs:
            progress = Progress(f"crossval fold {fold} ({n}/{len(folds)}) {what}", unit="recording")
            try:
                results[what] += score_all(mine, plan.root, models, plan.closed_loop, plan.rules, plan.workers,
                                           on_done=progress, smooth=plan.smooth if what == "folds" else None,
                                           journal=journal, what=what)
            finally:
                progress.close()
        results = {what: sorted(scores, key=lambda s: order[s.name]) for what, scores in results.items()}
        if plan.json_out:  # each finished fold's figures at once
            write_json(plan.json_out, _record(plan, pattern, results, folds, n))
    print(format_tables(results["folds"], results.get("peer", ())))
    if plan.json_out:
        print(f"json  {plan.json_out}")
    if plan.plot and plan.closed_loop:
        from tools.realdata.crossval_plot import plot_crossval

        plot_crossval({what: {"recordings": [s.as_dict() for s in scores]} for what, scores in results.items()},
                      plan.plot)
        print(f"plot  {plan.plot}")
    return 0


def _check_models(plan: CrossvalPlan, every: list[PublicRecording], recs: list[PublicRecording]) -> str:
    """The fold models' pattern, once the plot can be drawn, the recipe loads (and its recordings are fetched)
    or every fold's model is there, and the peer's: refused before hours of scoring, not after."""
    from tools.realdata.crossval import FOLD_FIELD, model_for
    from tools.realdata.foldtrain import fold_models
    from tools.realdata.recordings import require_fetched

    if plan.plot:
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            raise CommandError("--plot needs matplotlib", 'pip install -e ".[plots]"')
        if not plan.plot.resolve().parent.is_dir():
            raise CommandError(f"--plot {plan.plot}: no folder {plan.plot.parent}")
    pattern = plan.models or fold_models(plan.runs)
    expected = {Path(plan.peer)} if plan.peer else set()
    if plan.recipe:
        from models.training.recipe import load_recipe

        load_recipe(plan.recipe)  # a bad recipe is refused before any work
        require_fetched(every, plan.root, "recordings to train on")
    else:
        expected |= {model_for(pattern, r) for r in recs}
    missing = [str(p) for p in expected if not p.is_file()]
    if missing:
        raise CommandError(f"no model at {', '.join(sorted(missing))}",
                           f"train one per fold ({FOLD_FIELD} in --models): "
                           "rbc train --recipe R $(rbc data fold F --root ...), or give --recipe R")
    return pattern


def _record(plan: CrossvalPlan, pattern: str, results: dict[str, list[RecordingScore]], folds: list[str],
            done: int) -> dict[str, object]:
    """The ``--json`` record once the first ``done`` of ``folds`` are scored: the settings and the scores."""
    from protocol.runrecords import code_version
    from tools.realdata.crossval import summarise

    return {"code_version": code_version(), "root": str(plan.root), "models": pattern, "recipe": plan.recipe,
            "peer": plan.peer, "closed_loop": plan.closed_loop, "lane": plan.rules.lane,
            "max_offset_m": plan.rules.max_offset_m, "smooth": plan.smooth, "handback_s": plan.rules.handback_s,
            "folds_done": folds[:done], "folds": folds,
            **{what: {"recordings": [s.as_dict() for s in scores], "tracks": [t.__dict__ for t in summarise(scores)]}
               for what, scores in results.items()}}
