"""The unseen-worlds experiment (beyond the paper): eta over K generated worlds from the evaluation seeds.

The worlds are generated on the driver into ``OUT/worlds/world-SEED.json`` (so a run can be repeated
from its output folder) and their documents travel with every task, so a worker on another machine
(Ray) writes the same file where the run expects it. Aggregation is over worlds: mean ± std of the
per-world eta, the worst world, and how many needed no intervention.
"""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from types import ModuleType
from typing import Any

from protocol.errors import BadValue
from protocol.runrecords import file_sha256, read_json
from tools.evaluate.experiments import experiment, is_autonomous, run_eta
from tools.sim.track.files import track_text, write_track_file
from tools.sim.worldgen import GENERATOR_VERSION, WorldGenConfig, generate_world, world_seed_range

KEY = "unseen_worlds"
WORLDS_DIR = "worlds"


def eval_world_seeds(count: int, first: int | None = None) -> list[int]:
    """``count`` seeds from ``first`` (default: the start of the evaluation range), all held-out worlds."""
    held_out = world_seed_range("eval")
    first = held_out.start if first is None else first
    if count < 1:
        raise BadValue(f"--worlds must be >= 1, got {count}")
    if first not in held_out or first + count - 1 not in held_out:
        raise BadValue(f"unseen worlds come from the evaluation seeds {held_out.start:,}-{held_out.stop - 1:,}, "
                         f"not {first}-{first + count - 1} (training worlds would not be unseen)")
    return list(range(first, first + count))


def write_eval_worlds(out: Path, seeds: list[int], config: WorldGenConfig, resume: bool) -> dict[str, Any]:
    """Generate the worlds into ``out/worlds``; what results.json records about them.

    A resumed evaluation must find the same worlds it started with (its journaled runs drove them).
    """
    folder = out / WORLDS_DIR
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for seed in seeds:
        path = folder / f"world-{seed}.json"
        doc = generate_world(seed, config)
        if resume and path.is_file() and path.read_text(encoding="utf-8") != track_text(doc):
            raise BadValue(f"--resume: {path} is not the world this command generates (another --world-config "
                             "or generator version?); use a new --out, or drop --resume")
        paths[seed] = str(write_track_file(path, doc))
    return {"seeds": seeds, "seed_range": "eval", "generator_version": GENERATOR_VERSION,
            "config": asdict(config), "files": paths,
            "sha256": {str(s): file_sha256(p) for s, p in paths.items()}}


def track_doc(path: str) -> dict[str, Any]:
    return read_json(Path(path))


def summarize_worlds(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Mean ± std of eta over worlds (one run each), the worst world, and each world's run."""
    per = sorted(({"seed": r["value"], "eta": run_eta(r), "autonomous": is_autonomous(r),
                   "interventions": sum(lap.get("n_interventions", len(lap.get("interventions") or []))
                                        for lap in r["laps"]), "map": r.get("map")} for r in records),
                 key=lambda w: w["seed"])
    etas = [w["eta"] for w in per]
    worst = min(per, key=lambda w: (w["eta"], w["seed"])) if per else None
    return {"measure": "worlds", "title": experiment(KEY).title, "parameter": "world_seed", "n": len(per),
            "mean": statistics.fmean(etas) if etas else 0.0, "std": statistics.pstdev(etas) if len(etas) > 1 else 0.0,
            "autonomous": sum(w["autonomous"] for w in per),
            "worst": {"seed": worst["seed"], "eta": worst["eta"]} if worst else None, "worlds": per}


def format_worlds(entry: dict[str, Any]) -> str:
    """``η = 96.1 ± 5.2 % over 10 worlds (8 with no take-over; worst: world 1000004, 82.0 %)``."""
    if not entry.get("n"):
        return "n/a"
    worst = entry["worst"]
    return (f"η = {entry['mean']:.1f} ± {entry['std']:.1f} % over {entry['n']} worlds ({entry['autonomous']} with "
            f"no take-over; worst: world {worst['seed']}, {worst['eta']:.1f} %)")


def plot_worlds(entry: dict[str, Any], path: Path, plt: ModuleType) -> Path | None:  # plt: matplotlib.pyplot
    """The degree of autonomy per world as bars (green: no take-over, red: take-overs), the mean dashed."""
    worlds = entry.get("worlds") or []
    if not worlds:
        return None
    fig, ax = plt.subplots(figsize=(max(6.0, 0.45 * len(worlds) + 2), 3.2), dpi=110)
    xs = range(len(worlds))
    ax.bar(xs, [w["eta"] for w in worlds], color=["tab:green" if w["autonomous"] else "tab:red" for w in worlds])
    ax.axhline(entry["mean"], color="0.3", linestyle="--", linewidth=0.9, label=f"mean {entry['mean']:.1f} %")
    ax.set_xticks(list(xs), [str(w["seed"]) for w in worlds], rotation=60, fontsize=7)
    ax.set(xlabel=experiment(KEY).axis, ylabel="degree of autonomy η (%)",
           ylim=(min(0, min(w["eta"] for w in worlds) - 5), 105))
    ax.set_title(entry["title"], fontsize=10)
    ax.legend(loc="lower left", fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
