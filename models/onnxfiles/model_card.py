"""The model card of a bundled model: its data, configuration, validation MSE and closed-loop result."""

from __future__ import annotations

import json
from pathlib import Path

from drive_server.runrecords import read_json
from models.networks.architectures import ARCHITECTURES as TABLES
from models.networks.runfiles import CONFIG, HISTORY, read_history

_NAMES = {"shallow": "The paper's shallow CNN", "pilotnet": "NVIDIA's PilotNet",
          "shallow-wide": "The shallow CNN, twice the width and filters"}
#: Each network's card line; sizes from its layer table (models.networks.architectures), said there once.
ARCHITECTURES = {n: f"{_NAMES[n]} ({a.params:,} parameters, {a.width}x{a.height} input)" for n, a in TABLES.items()}


def _approach(approach: str, resolved: dict) -> str:
    if approach == "nvidia":
        return ("NVIDIA's approach (centre camera only, crop, YUV, no zero-steer balancing; random flip, a "
                "horizontal viewpoint shift and milder brightness)")
    return (f"the paper's approach (ours: zero-steer balancing lambda = {resolved['deletion_rate']}, "
            "the augmentations of Table 5)")


def _validation(cfg: dict, history: list[dict]) -> str:
    """The exported epoch's validation MSE and how it was measured (runs before issue 13: random split, last)."""
    result = cfg.get("result")
    if result is None:
        return f"{history[-1]['val_loss']:.5f} (final epoch, random split)"
    m = result["val_metrics"]
    return (f"{result['val_mse']:.5f} (epoch {result['exported_epoch']}, export {result['export']}, "
            f"{result['split']} split; Pearson r {m['r']:.2f}, always-0 MSE {m['zero_mse']:.5f})")


def card(run_dir: Path, behavior: str, recipe: str, sim_result: dict, onnx_name: str) -> str:
    cfg = read_json(run_dir / CONFIG)
    history = read_history(run_dir / HISTORY)
    c, r = cfg["config"], cfg["resolved"]
    train_s = sum(h["seconds"] for h in history)
    lap = sim_result["laps"][0]
    sc = sim_result["config"]
    model_flag = "" if onnx_name == f"{behavior}.onnx" else f" --model models/pretrained/{onnx_name}"
    lines = [
        f"# `{onnx_name}`: {behavior} driving behavior",
        "",
        f"{ARCHITECTURES.get(c['arch'], c['arch'])} trained with {_approach(c['approach'], r)} on data recorded by "
        "`rbc collect` in the headless simulator.",
        "",
        "| | |", "|---|---|",
        f"| data | {r['train_samples']} training + {r['val_samples']} validation samples "
        f"({r['zero_steer_train_samples']} zero-steer training samples before balancing) |",
        f"| training | {c['arch']}, {r['epochs']} epochs x {r['steps_per_epoch']} steps of {c['batch_size']}, "
        f"augmentation loops {c['aug_loops']}, Adam {c['learning_rate']}, MSE, seed {c['seed']} |",
        f"| training time | {train_s / 60:.1f} min on a 2-core CPU |",
        f"| validation MSE | {_validation(cfg, history)} |",
        f"| preprocessing | {json.dumps(cfg['contract'])} (in the ONNX metadata) |",
        f"| closed loop, no variation | eta = {lap['eta']:.1f} % on `{sc['track']}`"
        + (f" with {sc['cones']} cones (seed {sc['cone_seed']})" if sc["cones"] else "")
        + f", {lap['n_interventions']} interventions, lap {lap['lap_time_s']:.0f} s at "
          f"{lap['mean_speed_kmh']:.1f} km/h mean (limit {sc['speed_limit_kmh']:g}), "
          f"cross-track error RMS {lap['cte_rms_m']:.2f} m |",
        "",
        f"Reproduce ({'one command' if len(recipe.strip().splitlines()) == 1 else 'these commands'}; "
        "deterministic per seed):",
        "",
        "```bash",
        recipe,
        "```",
        "",
        f"Robustness (the paper's eight experiments): `rbc eval --behavior {behavior}{model_flag} "
        f"--out eval/{Path(onnx_name).stem}`.",
        "",
    ]
    return "\n".join(lines)
