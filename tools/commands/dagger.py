"""``rbc dagger``: DAgger on the headless simulator, its behavioural-cloning baseline, and the two compared."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from tools.errors import CommandError

log = logging.getLogger("rbc.dagger")

DEFAULT_ROUNDS = 4
FIRST_BUDGET = 2000


def add_arguments(p: argparse.ArgumentParser) -> None:
    from tools.dagger.config import DEFAULT_RECIPE, TRACKS, DaggerConfig

    d = DaggerConfig  # the defaults, defined once
    p.add_argument("--out", type=Path, required=True,
                   help="output folder: round-RR/ (data, train, eval, record.json) per round, summary.json, "
                        "rounds.md; with --compare the report's folder")
    p.add_argument("--baseline", choices=("bc",), default=None,
                   help="bc: the behavioural-cloning baseline, the same rounds with the expert driving every step "
                        "(default: DAgger)")
    p.add_argument("--rounds", type=int, default=DEFAULT_ROUNDS,
                   help=f"rounds (default %(default)s); without --frames-per-round the expert frames double each "
                        f"round from {FIRST_BUDGET:,}")
    p.add_argument("--frames-per-round", type=int, default=None, metavar="K",
                   help="expert-labelled frames collected per round (default: doubling budgets, see --rounds)")
    p.add_argument("--budgets", default=None, metavar="N,N,...",
                   help="expert frames after each round, cumulative (e.g. 2000,4000,8000,16000); instead of --rounds "
                        "and --frames-per-round")
    p.add_argument("--recipe", default=DEFAULT_RECIPE,
                   help="rbc train recipe of every round, a bundled name or a .toml file (default %(default)s)")
    p.add_argument("--epochs", type=int, default=None, help="instead of the recipe's epochs")
    p.add_argument("--max-steps-per-epoch", type=int, default=None, metavar="N",
                   help="instead of the recipe's: cap training steps per epoch (quick runs)")
    p.add_argument("--beta0", type=float, default=d.beta0,
                   help="probability that the expert drives a step, scaled by --beta-decay per round; round 0 is "
                        "always the expert's (default %(default)s)")
    p.add_argument("--beta-decay", type=float, default=d.beta_decay,
                   help="beta of round r = beta0 * beta_decay ** r (default %(default)s)")
    p.add_argument("--episode-steps", type=int, default=d.episode_steps,
                   help="steps of 1/15 s per episode, each on a new training world (default %(default)s)")
    p.add_argument("--eval-worlds", type=int, default=d.eval_worlds,
                   help="unseen generated worlds from the evaluation range every round is scored on "
                        "(default %(default)s)")
    p.add_argument("--eval-world-seed", type=int, default=None, metavar="S",
                   help="first evaluation world (default: the start of the evaluation range)")
    p.add_argument("--eval-world-config", default=None, metavar="JSON",
                   help="generator settings of the evaluation worlds, a JSON object of WorldGenConfig fields or a "
                        "file holding one, as rbc eval --world-config (default: the documented distribution)")
    p.add_argument("--tracks", nargs="*", default=list(TRACKS), metavar="TRACK",
                   help="built-in tracks scored too (default: %(default)s)")
    p.add_argument("--perturbations", action="store_true",
                   help="score Table 9's orientation and light rows on lake too (rbc eval's range searches)")
    p.add_argument("--cameras", type=int, choices=(1, 3), default=d.cameras,
                   help="frames recorded per step: 1 = centre, 3 = with left/right (default %(default)s)")
    p.add_argument("--seed", type=int, default=d.seed,
                   help="worlds, spawns, who drives each step, and training (default %(default)s)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out at its first unfinished round, with the same flags "
                        "(more --rounds may be added)")
    p.add_argument("--workers", type=int, default=1,
                   help="evaluation runs at once, one process each (default %(default)s)")
    p.add_argument("--threads", type=int, default=None,
                   help="PyTorch threads of training (default: rbc train's, cores - 1)")
    p.add_argument("--compare", nargs=2, type=Path, default=None, metavar=("DAGGER_OUT", "BC_OUT"),
                   help="instead of running: compare a finished DAgger run with its --baseline bc run; writes "
                        "--out/comparison.md, comparison.json and curve.png")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def _budgets(args: argparse.Namespace) -> tuple[int, ...]:
    from tools.dagger.config import budgets_from

    if args.budgets:
        try:
            return tuple(int(b) for b in args.budgets.split(","))
        except ValueError:
            raise CommandError(f"--budgets {args.budgets!r}: expected rising numbers of frames, e.g. "
                               "2000,4000,8000") from None
    if args.frames_per_round:
        return budgets_from(args.rounds, args.frames_per_round)
    if args.rounds < 1:
        raise CommandError(f"--rounds must be >= 1, got {args.rounds}")
    return tuple(FIRST_BUDGET * 2 ** r for r in range(args.rounds))


def _world_config(text: str | None) -> dict | None:
    """--eval-world-config as a dict (inline JSON or a file), checked by rbc eval's own parser."""
    if text is None:
        return None
    import json

    from tools.sim.worldgen.config import parse_world_config

    parse_world_config(text)
    return json.loads(Path(text).read_text(encoding="utf-8") if not text.lstrip().startswith("{") else text)


def run(args: argparse.Namespace) -> int:
    import importlib.util

    if args.compare:
        from tools.dagger.report import compare

        compare(args.compare[0], args.compare[1], args.out)
        print((args.out / "comparison.md").read_text(encoding="utf-8"), end="")
        print(f"wrote {args.out / 'comparison.md'}, comparison.json and {args.out / 'curve.png'}")
        return 0
    if importlib.util.find_spec("gymnasium") is None:
        raise CommandError("rbc dagger drives the Gymnasium environment rbc/Drive-v0: gymnasium is not installed",
                           'pip install -e ".[gym,train]"')
    from tools.dagger.config import DaggerConfig
    from tools.dagger.loop import Stopped, headline
    from tools.dagger.loop import run as run_rounds

    config = DaggerConfig(mode=args.baseline or "dagger", budgets=_budgets(args), beta0=args.beta0,
                          beta_decay=args.beta_decay, episode_steps=args.episode_steps, recipe=args.recipe,
                          epochs=args.epochs, max_steps_per_epoch=args.max_steps_per_epoch,
                          eval_worlds=args.eval_worlds, eval_world_seed=args.eval_world_seed,
                          eval_world_config=_world_config(args.eval_world_config),
                          tracks=tuple(args.tracks), perturbations=args.perturbations, seed=args.seed,
                          cameras=args.cameras)
    from models.training.recipe import find_recipe

    find_recipe(config.recipe)  # an unknown recipe is an error before anything is written
    try:
        records = run_rounds(config, args.out, resume=args.resume, workers=args.workers, threads=args.threads,
                             progress=not args.no_progress)
    except (KeyboardInterrupt, Stopped) as exc:
        print(f"interrupted ({exc or 'Ctrl-C'}); finished rounds are kept in {args.out}: continue with the same "
              f"command plus --resume")
        return 130
    print(f"\n{'DAgger' if config.mode == 'dagger' else 'Behavioural cloning'}, {len(records)} rounds, "
          f"seed {config.seed}:")
    for record in records:
        print(f"  round {record['round']} (beta {record['beta']:.3g}, {record['expert_frames']:,} expert frames): "
              f"{headline(record)}")
    print(f"wrote {args.out / 'summary.json'} and {args.out / 'rounds.md'}")
    return 0
