"""``rbc data crossval``: every public recording scored by the model of its fold (trained first with
``--recipe``), open and closed loop, resumable from its journal; tables, JSON and a picture.
Library: :mod:`tools.realdata.crossval`."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.arguments import smooth_alpha


def crossval(args: argparse.Namespace) -> int:
    from drive_server.runrecords import code_version, write_json
    from tools.console import Progress
    from tools.drivelog.loop import LoopRules
    from tools.errors import CommandError
    from tools.realdata.crossval import FOLD_FIELD, ScoreJournal, journal_for, model_for, score_all, summarise
    from tools.realdata.crossval_tables import format_tables
    from tools.realdata.foldtrain import fold_models, train_fold
    from tools.realdata.recordings import public_recordings, require_fetched, select

    alpha = smooth_alpha(args)
    every = public_recordings()
    recs = select(every, args.track, args.name)
    if not recs:
        raise CommandError("no public recording among those named")
    if not 1 <= args.workers <= 64:
        raise CommandError("--workers must be 1..64")
    rules = LoopRules(lane=args.lane, max_offset_m=args.max_offset,  # they check their own ranges
                      **({} if args.handback is None else {"handback_s": args.handback}))
    if args.plot:  # before hours of scoring, not after
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            raise CommandError("--plot needs matplotlib", 'pip install -e ".[plots]"')
        if not Path(args.plot).resolve().parent.is_dir():
            raise CommandError(f"--plot {args.plot}: no folder {Path(args.plot).parent}")
    pattern = args.models or fold_models(args.runs)
    expected = {Path(args.peer)} if args.peer else set()
    if args.recipe:
        from models.training.recipe import load_recipe

        load_recipe(args.recipe)  # a bad recipe is refused before any work
        require_fetched(every, args.root, "recordings to train on")
    else:
        expected |= {model_for(pattern, r) for r in recs}
    missing = [str(p) for p in expected if not p.is_file()]
    if missing:
        raise CommandError(f"no model at {', '.join(sorted(missing))}",
                           f"train one per fold ({FOLD_FIELD} in --models): "
                           "rbc train --recipe R $(rbc data fold F --root ...), or give --recipe R")
    require_fetched(recs, args.root)
    closed = not args.no_closed_loop
    journal = ScoreJournal(journal_for(args.json) if args.json else None)
    runs = [("folds", pattern)] + ([("peer", args.peer)] if args.peer else [])
    results: dict[str, list] = {what: [] for what, _ in runs}
    folds = sorted({r.fold for r in recs})
    for n, fold in enumerate(folds, start=1):
        mine = [r for r in recs if r.fold == fold]
        if args.recipe:
            print(f"fold {fold} ({n} of {len(folds)}): model {model_for(pattern, mine[0])}", flush=True)
            if train_fold(args.recipe, fold, every, args.root, args.runs) is None:
                print(f"interrupted while training fold {fold}; the same command continues it", flush=True)
                return 130
        for what, models in runs:
            progress = Progress(f"crossval fold {fold} ({n}/{len(folds)}) {what}", unit="recording")
            try:
                results[what] += score_all(mine, args.root, models, closed, rules, args.workers, on_done=progress,
                                           smooth=alpha if what == "folds" else None, journal=journal, what=what)
            finally:
                progress.close()
        if args.json:  # each finished fold's figures at once
            order = {r.name: i for i, r in enumerate(recs)}
            write_json(args.json, {
                "code_version": code_version(), "root": str(args.root), "models": pattern, "recipe": args.recipe,
                "peer": args.peer, "closed_loop": closed, "lane": args.lane, "max_offset_m": args.max_offset,
                "smooth": alpha, "handback_s": rules.handback_s, "folds_done": folds[:n], "folds": folds,
                **{what: {"recordings": [s.as_dict() for s in sorted(scores, key=lambda s: order[s.name])],
                          "tracks": [t.__dict__ for t in summarise(sorted(scores, key=lambda s: order[s.name]))]}
                   for what, scores in results.items()}})
    order = {r.name: i for i, r in enumerate(recs)}
    results = {what: sorted(scores, key=lambda s: order[s.name]) for what, scores in results.items()}
    print(format_tables(results["folds"], results.get("peer", ())))
    if args.json:
        print(f"json  {args.json}")
    if args.plot and closed:
        from tools.realdata.crossval_plot import plot_crossval

        plot_crossval({what: {"recordings": [s.as_dict() for s in scores]} for what, scores in results.items()},
                      args.plot)
        print(f"plot  {args.plot}")
    return 0
