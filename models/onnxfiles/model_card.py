"""A model's card: what it is, how to use it, how to measure it and how to rebuild it (``rbc model-card``).

Every fact comes from what training recorded (the run's ``config.json``) and from what the model file says about
itself (its ONNX metadata). A card holds no result figures, which live in ``results/*.json`` and on
docs/results.md: it says how to measure the model instead, and names the resolved recipe saved beside it.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from drive_server.serving.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY
from drive_server.serving.settings import GAIN, GAIN_OLD_NAMES, NO_GAIN, SERVING_KEY, Serving
from drive_server.serving.smoothing import NAME, OFF, OLD_NAMES
from models.networks.architectures import ARCHITECTURES
from models.networks.runfiles import RunPaths, RunRecord
from models.onnxfiles.card_text import block, command, count, quoted, shown, wrap
from models.onnxfiles.onnx_metadata import ModelInfo
from protocol.errors import BadValue
from protocol.facts import FRAME_HEIGHT

#: The documentation the cards link to (relative to the card, as the bundled cards do).
DOCS = Path(__file__).resolve().parents[2] / "docs"
NETWORKS = {"shallow": "the paper's shallow CNN", "pilotnet": "NVIDIA's PilotNet",
            "shallow-wide": "the shallow CNN at twice the width, with twice the filters"}
#: Recipe keys beyond the paper, and the value that leaves each off.
EXTRAS = {"label_smoothing_frames": 0, "balance_recordings": False, "centre_gain": 0.0, "yaw_aug": 0.0,
          "edge_gain": 0.0}
#: The rig of a model of ours whose record names none: it predates the unity rig.
LEGACY_RIG = "classic"


@dataclass(frozen=True)
class ModelFile:
    """What a model file says about itself."""

    path: Path  # as the card's commands name it
    info: ModelInfo  # its record (rbc.model); {} if none
    contract: dict[str, Any]  # its preprocessing (rbc.preprocess); {} if none
    smoothing: float = OFF  # the steering smoothing it asks drive_server for (1: off)
    gain: float = 1.0  # the steering gain it asks drive_server for (drive_server.serving.settings; 1: none)


@dataclass(frozen=True)
class CardSource:
    """What a card is written from."""

    record: RunRecord  # what the run recorded
    model: ModelFile
    recipe: Path  # the resolved recipe beside the card, as the commands name it
    home: str  # rbc sim flags of the behavior's scene, e.g. "--track lake"
    purpose: str = ""  # the card's one-line purpose; empty: one said from the run
    data_commands: tuple[str, ...] = ()  # commands that made its data, quoted before rbc train
    recipe_name: str = ""  # how rbc train --recipe names it where it is bundled; empty: by its path


def read_model_file(path: Path) -> ModelFile:
    """The metadata of the ONNX model at ``path``; BadValue if it is not one."""
    import onnxruntime as ort

    try:
        meta = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).get_modelmeta()
        found = meta.custom_metadata_map
        info, contract = (json.loads(found.get(k) or "{}") for k in (METADATA_MODEL_INFO_KEY, METADATA_KEY))
        serving = Serving.from_json(found.get(SERVING_KEY))
    except Exception as exc:  # ONNX Runtime's own errors, bad JSON, a bad rbc.serving
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
        raise BadValue(f"{path}: not a model file of ours ({first})") from None
    return ModelFile(path, cast(ModelInfo, info) if isinstance(info, dict) else {},  # a JSON object
                     contract if isinstance(contract, dict) else {}, serving.smoothing, serving.gain)


def card(src: CardSource) -> str:
    """The card, Markdown: purpose, What it is, How to use it, How well it drives, Known limits, Reproduce."""
    parts = [_title(src), _what_it_is(src), _how_to_use(src), _how_well(src), _limits(src), _reproduce(src)]
    return "\n\n".join(parts) + "\n"


# --- the sections -------------------------------------------------------------------------------------------------

def _title(src: CardSource) -> str:
    c = src.record.config
    rig = _rig(src)
    filmed = f"filmed by the `{rig}` camera rig" if rig else "filmed by several camera rigs"
    network = NETWORKS.get(c["arch"], c["arch"])
    purpose = src.purpose or (f"{network[0].upper()}{network[1:]} trained for the {c['behavior']} "
                              f"[behavior]({_link(src, 'glossary.md', 'behavior')}) on "
                              f"{count(len(c['data']), 'recording folder')} {filmed}.")
    return f"# `{src.model.path.name}`: a {c['behavior']} driving model\n\n{wrap(purpose)}"


def _what_it_is(src: CardSource) -> str:
    c = src.record.config
    params = src.model.info.get("parameters") or ARCHITECTURES[c["arch"]].params
    items = [("Network", f"{NETWORKS.get(c['arch'], c['arch'])}, {params:,} parameters."),
             ("Input", _input(src.model.contract or src.record.contract)), ("Camera", _camera(src)),
             ("Training data", _training_data(src.record)), ("Validation", _validation(src.record)),
             ("Training", _training(src)), ("Its answer", _answer(src))]
    return "## What it is\n\n" + "\n".join(wrap(f"- **{label}**: {text}", "  ") for label, text in items)


def _how_to_use(src: CardSource) -> str:
    path = quoted(src.model.path)
    text = ("`rbc sim` drives one lap of the headless simulator in-process (`--track world:SEED`: a generated "
            "world); `drive_server` serves the model to the Udacity simulator "
            f"([Drive the Udacity simulator]({_link(src, 'unity.md')})).")
    return block("## How to use it", [f"rbc sim --model {path} {src.home}", f"drive_server --model {path}"], text)


def _how_well(src: CardSource) -> str:
    c, path, stem = src.record.config, quoted(src.model.path), src.model.path.stem
    val = [shown(v) for v in c.get("val_data", [])]
    rec = quoted(val[0]) if val else "DIR"
    commands = [f"rbc sim --model {path} {src.home} --json lap.json",
                f"rbc eval --behavior {c['behavior']} --model {path} --out eval/{stem}",
                f"rbc eval --behavior {c['behavior']} --model {path} --experiments unseen_worlds --worlds 20 "
                f"--out eval/{stem}-unseen",
                f"rbc score --data {rec} --model {path}", f"rbc drive-log --data {rec} --model {path}"]
    which = (f"`{val[0]}`, a recording it was validated on and never trained on" if val else
             "DIR, a recording of the Udacity simulator it never trained on (`rbc data fetch --out real` fetches "
             "the public ones)")
    head = ("This card holds no figures: these commands measure the model, and the "
            f"[Results]({_link(src, 'results.md')}) page has the bundled models' figures.")
    text = ("`rbc sim` drives one lap and reports its degree of autonomy and take-overs; `rbc eval` runs the "
            "paper's eight experiments on the behavior's track, and with `--experiments unseen_worlds` laps of "
            f"generated roads it never saw; `rbc score` (open loop) and `rbc drive-log` (closed loop) use {which}. "
            f"[Evaluate a model]({_link(src, 'evaluate.md')}) says what each answers.")
    return block("## How well it drives", commands, text, head)


def _limits(src: CardSource) -> str:
    c = src.record.config
    items = ["It knows only the roads, light and camera of its training data; anywhere else, measure it first "
             "([How well it drives](#how-well-it-drives))."]
    if _split_kind(src.record) == "random":
        link = _link(src, "glossary.md", "held-out")
        items.append("Its validation frames were drawn at random from the recordings it trained on, neighbours of "
                     f"training frames: its validation error is optimistic ([held-out]({link})).")
    if src.model.info.get("mirror_average"):
        items.append("The mirror average drives the middle of the road: it does not keep to one lane.")
    if c.get("max_steps_per_epoch"):
        items.append(f"Its epochs were cut to {c['max_steps_per_epoch']} steps (`max_steps_per_epoch`): a quick "
                     "run, not the full schedule.")
    return "## Known limits\n\n" + "\n".join(wrap(f"- {item}", "  ") for item in items)


def _reproduce(src: CardSource) -> str:
    c = src.record.config
    head = (f"Its settings are its recipe, `{src.recipe.as_posix()}` beside this card: every key, resolved from the "
            "run's record. These commands rebuild it, deterministic per seed:")
    text = "" if src.data_commands else ("It needs the data folders it was trained and validated on: `rbc collect` "
                                         "records headless ones, `rbc data fetch` the public real recordings.")
    commands = [*src.data_commands, _train_command(src, c), *_file_command(src, c)]
    return block("## Reproduce", commands, text, head)


# --- the facts ----------------------------------------------------------------------------------------------------

def _input(contract: dict[str, Any]) -> str:
    top, bottom = contract["crop_top"], contract["crop_bottom"]
    crop = f"the whole {FRAME_HEIGHT}-row picture" if (top, bottom) == (0, FRAME_HEIGHT) else f"rows {top}-{bottom}"
    low, high = contract["offset"], round(255 * contract["scale"] + contract["offset"], 4)
    text = (f"one camera frame, {crop} resized to {contract['width']}x{contract['height']}, "
            f"{contract['color'].upper()}, scaled to {low:g}..{high:g}")
    if contract.get("decode_reduce", 0) > 1:
        text += f"; the JPEG is decoded at 1/{contract['decode_reduce']} size"
    if contract.get("blank_columns"):
        text += f"; the outer {contract['blank_columns']} columns on each side repeat the next one inward"
    return text + (". The settings travel in the ONNX file's metadata (`rbc.preprocess`), so `drive_server` "
                   "prepares frames the same way.")


def _camera(src: CardSource) -> str:
    rig = _rig(src)
    if not rig:
        return ("frames of several [camera rigs](" + _link(src, "glossary.md", "camera-rig") + "); the headless "
                "simulator films it with its default rig.")
    return (f"the `{rig}` [camera rig]({_link(src, 'glossary.md', 'camera-rig')}). The model's record names it, so "
            "`rbc sim`, `rbc eval` and `rbc demo` film it with that rig.")


def _training_data(record: RunRecord) -> str:
    c, r, rows = record.config, record.resolved, record.rows
    text = _folders(record, c["data"])
    if rows.get("stride", 1) > 1:
        text += f"; 1 row in {rows['stride']} used"
    if c.get("min_speed", 0) > 0:
        text += f"; rows slower than {c['min_speed']:g} {c.get('min_speed_unit', 'mph')} dropped"
    zero = r.get("zero_steer_train_samples")
    return text + f": {r['train_samples']:,} training samples" + (
        f" ({zero:,} of them steering 0, before balancing)." if zero is not None else ".")


def _validation(record: RunRecord) -> str:
    c, r = record.config, record.resolved
    if c.get("val_data"):
        text = f"the recordings {_folders(record, c['val_data'])}: {r['val_samples']:,} samples, never trained on."
    else:
        kind = _split_kind(record)
        how = {"blocks": f"in stretches of {c.get('block_frames')} frames (their neighbours dropped from training)",
               "random": "at random (the paper's split)", "recordings": "as whole recordings"}.get(kind, kind)
        text = f"{r['val_samples']:,} samples of the same data, held out {how}."
    result = record.result or {}
    if c.get("export") == "best":
        return text + (f" They chose the exported epoch, the one with the lowest validation MSE (epoch "
                       f"{result.get('exported_epoch', '?')} of {r['epochs']}).")
    return text + " The last epoch is exported, so they chose nothing."


def _training(src: CardSource) -> str:
    c, r = src.record.config, src.record.resolved
    link = _link(src, "glossary.md", "approach")
    if c["approach"] == "nvidia":
        text = f"NVIDIA's [approach]({link}) (centre camera only, crop, YUV, no zero-steer balancing)"
    else:
        scale = ", brightness changed relative to the frame's own" if c.get("brightness_mode") == "scale" else ""
        text = (f"the paper's [approach]({link}) (zero-steer balancing with lambda = {r['deletion_rate']:g}, the "
                f"paper's augmentations{scale})")
    text += (f", {count(r['epochs'], 'epoch')} of {r['steps_per_epoch']:,} steps of {c['batch_size']} samples "
             f"({c['aug_loops']} augmentation loops), {r.get('optimizer', 'Adam')} at learning rate "
             f"{c['learning_rate']:g}, {r.get('loss', 'MSE')} loss, seed {c['seed']}.")
    extras = [f"`{k} = {json.dumps(c[k])}`" for k, off in EXTRAS.items() if c.get(k, off) != off]
    return text + (f" Beyond the paper: {', '.join(extras)} (the recipe says what each does)." if extras else "")


def _answer(src: CardSource) -> str:
    info, c, smooth, gain = src.model.info, src.record.config, src.model.smoothing, src.model.gain
    mirror, baked = bool(info.get("mirror_average")), float(info.get("output_scale", 1.0))  # baked: older files
    if not mirror and baked == 1.0 and smooth == OFF and gain == NO_GAIN:
        return "the network's steering, as trained."
    link = _link(src, "glossary.md", "mirror-average-gain-smoothing")
    text = (f"the file answers the [mirror average]({link}) of the network, (f(x) - f(mirrored x)) / 2" if mirror
            else f"the file answers the network's steering ([gain, smoothing]({link}))")
    text += f", times {baked:g} inside the graph." if baked != 1.0 else "."
    if gain != NO_GAIN:
        text += (f" `drive_server` multiplies it by a gain of {gain:g} (`--gain` changes it; `rbc score` scores the "
                 f"network without it).")
    if smooth < OFF:
        text += f" `drive_server` smooths its steering with {smooth:g}."
    text += " The network's weights are the trained ones"
    return text + ("; `rbc mirror` made the file." if mirror and not c.get("mirror_average") else ".")


def _train_command(src: CardSource, c: dict[str, Any]) -> str:
    words = ["rbc", "train", "--recipe", src.recipe_name or src.recipe.as_posix()]
    words += [w for d in c["data"] for w in ("--data", shown(d))]
    words += [w for d in c.get("val_data", []) for w in ("--val-data", shown(d))]
    return command([*words, "--out", c["out"]])


def _file_command(src: CardSource, c: dict[str, Any]) -> list[str]:
    """How the run's model.onnx becomes the card's file: nothing, a copy, or ``rbc mirror``."""
    made = RunPaths(Path(c["out"])).model
    if os.path.normpath(made) == os.path.normpath(src.model.path):
        return []
    words = ["cp", made.as_posix(), src.model.path.as_posix()]
    if src.model.info.get("mirror_average") and not c.get("mirror_average"):
        words = ["rbc", "mirror", made.as_posix(), "--out", src.model.path.as_posix()]
        asked = next((c[k] for k in (NAME, *OLD_NAMES) if k in c), OFF)  # a run stored before the one name: old
        if src.model.smoothing != asked:
            words += ["--serve-smooth", f"{src.model.smoothing:g}"]
        asked_gain = next((c[k] for k in (GAIN, *GAIN_OLD_NAMES) if k in c), NO_GAIN)
        words += ["--gain", f"{src.model.gain:g}"] if src.model.gain != asked_gain else []
    return [command(words)]


# --- wording ------------------------------------------------------------------------------------------------------

def _rig(src: CardSource) -> str:
    """The rig the model learnt from ('' for several)."""
    return src.model.info.get("camera_rig", LEGACY_RIG)


def _split_kind(record: RunRecord) -> str:
    split = record.resolved.get("split")
    return split["kind"] if isinstance(split, dict) else record.config.get("split", "random")


def _folders(record: RunRecord, folders: list[str]) -> str:
    """``folders`` with their rows, from the run's per-log report (one log per folder, training's then
    validation's, in order)."""
    c, logs = record.config, record.logs
    names = [*c["data"], *c.get("val_data", [])]
    rows = {n: log["rows"] for n, log in zip(names, logs, strict=False)} if len(logs) == len(names) else {}
    return ", ".join(f"`{shown(f)}`" + (f" ({rows[f]:,} rows)" if f in rows else "") for f in folders)


def _link(src: CardSource, page: str, anchor: str = "") -> str:
    """A docs page (``#anchor``) as a link relative to the card's folder."""
    rel = Path(os.path.relpath(DOCS / page, src.recipe.parent.resolve())).as_posix()
    return rel + (f"#{anchor}" if anchor else "")
