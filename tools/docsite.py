"""The generated pages of the documentation site: the command reference and the Python API, from the code.

MkDocs runs this file as a hook (``mkdocs.yml``: ``hooks``). A page holding ``<!-- generated: commands -->``
gets every ``rbc`` subcommand's and ``drive_server``'s own ``--help`` text, built from the argparse parsers
the commands use, so the reference cannot drift from the flags; ``<!-- generated: api -->`` gets the
signatures and docstrings of :data:`API`, the few Python entry points a user scripts against; and
``<!-- generated: readme -->`` (the home page) gets the README, its links made relative to ``docs/``, so
the front door is written once; ``<!-- generated: models -->`` gets a table of the bundled models read from
their own ONNX metadata; and every ``<!-- results NAME TABLE -->`` block is rendered afresh from its result
record (``tools/results/``), so a results table cannot differ from the figures that were measured.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse

    from mkdocs.config.defaults import MkDocsConfig
    from mkdocs.structure.files import Files
    from mkdocs.structure.pages import Page

README_MARKER = "<!-- generated: readme -->"
COMMANDS_MARKER = "<!-- generated: commands -->"
API_MARKER = "<!-- generated: api -->"
MODELS_MARKER = "<!-- generated: models -->"
#: Width of the help texts (argparse wraps to the terminal; the page must not depend on the builder's).
HELP_COLUMNS = 80
#: The widest line of a code block on the site (tests/test_docs_layout.py): a longer signature is split.
CODE_COLUMNS = 100
#: A dataclass default longer than this is shown as ``Name(...)`` (its fields are on its own entry).
SIGNATURE_DEFAULT_CHARS = 40

#: The public Python entry points, in the order a user meets them: ``module:name``.
API: tuple[str, ...] = (
    "protocol.datalog:read_log",
    "tools.sim.collect.dataset:CollectConfig",
    "tools.sim.collect.dataset:collect",
    "tools.sim.track.files:load_track",
    "tools.sim.worldgen.generate:generate_world",
    "tools.sim.worldgen.generate:write_world",
    "tools.sim.driving.scenario:ScenarioConfig",
    "tools.sim.driving.session:run_scenario",
    "models.training.train_config:TrainConfig",
    "models.training.train:train",
    "drive_server.serving.model:SteeringModel",
    "drive_server.serving.pipeline:DrivePipeline",
    "tools.evaluate.suite:run_suite",
    "tools.envs.drive_env:DriveEnv",
    "tools.envs.config:DriveEnvConfig",
    "tools.envs.config:RewardConfig",
    "tools.envs.expert:ExpertPolicy",
    "tools.envs.policy:OnnxPolicy",
    "tools.envs.worlds:WorldDistribution",
    "tools.envs.affinity:pin_workers",
)


def _help(parser: argparse.ArgumentParser) -> str:
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_COLUMNS)
    try:
        return parser.format_help()
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous


def commands_markdown() -> str:
    """Each command's ``--help`` as a section; a command whose extra is missing says which one."""
    from drive_server.cli import build_parser
    from tools.cli import SUBCOMMANDS, subcommand_parser

    out = ["## drive_server", "", "```text", _help(build_parser()).rstrip(), "```", ""]
    for cmd in SUBCOMMANDS:
        out += [f"## rbc {cmd.name}", "", cmd.help + ".", ""]
        try:
            module = importlib.import_module(cmd.module)
        except ModuleNotFoundError as exc:
            out += [f"(Its help needs the `{cmd.extra or exc.name}` extra installed where the site is built.)", ""]
            continue
        out += ["```text", _help(subcommand_parser(cmd, module)).rstrip(), "```", ""]
    return "\n".join(out)


def _entry(path: str) -> str:
    module_name, name = path.split(":")
    obj = getattr(importlib.import_module(module_name), name)
    doc = inspect.getdoc(obj) or ""
    fields = getattr(obj, "__dataclass_fields__", None) if inspect.isclass(obj) else None
    lines = [f"## `{name}`", "", f"`{module_name}`", ""]
    if fields is not None:  # a config: its fields and defaults (the defaults are defined there, once)
        if doc.startswith(f"{name}("):
            doc = ""  # the dataclass's generated docstring repeats the signature
        lines += [doc, "", "| field | type | default |", "|---|---|---|"]
        for field in fields.values():
            if field.default is not dataclasses.MISSING:
                default = f"`{field.default!r}`"
            elif field.default_factory is not dataclasses.MISSING:
                default = f"`{field.default_factory.__name__}()`"
            else:
                default = "(required)"
            kind = field.type if isinstance(field.type, str) else getattr(field.type, "__name__", str(field.type))
            lines.append(f"| `{field.name}` | `{kind.replace(' | ', ' or ')}` | {default} |")
        return "\n".join([*lines, ""])
    kind = "class" if inspect.isclass(obj) else "def"
    return "\n".join([*lines, "```python", _signature(obj, f"{kind} {name}"), "```", "", doc, ""])


def _parameter(p: inspect.Parameter) -> str:
    """A parameter as written in code: annotations unquoted, a long dataclass default as ``Name(...)``."""
    stars = "*" if p.kind is p.VAR_POSITIONAL else "**" if p.kind is p.VAR_KEYWORD else ""
    text = stars + p.name
    if p.annotation is not p.empty:
        text += ": " + (p.annotation if isinstance(p.annotation, str) else inspect.formatannotation(p.annotation))
    if p.default is not p.empty:
        default = repr(p.default)
        if len(default) > SIGNATURE_DEFAULT_CHARS and dataclasses.is_dataclass(p.default):
            default = f"{type(p.default).__name__}(...)"
        text += (" = " if p.annotation is not p.empty else "=") + default
    return text


def _signature(obj: object, head: str) -> str:
    """``head(parameters) -> returns`` on one line where it fits :data:`CODE_COLUMNS`, else a parameter a line."""
    try:
        sig = inspect.signature(obj)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return f"{head}(...)"
    parts: list[str] = []
    params = list(sig.parameters.values())
    for k, p in enumerate(params):
        if p.kind is p.KEYWORD_ONLY and (k == 0 or params[k - 1].kind not in (p.KEYWORD_ONLY, p.VAR_POSITIONAL)):
            parts.append("*")
        parts.append(_parameter(p))
        if p.kind is p.POSITIONAL_ONLY and (k + 1 == len(params) or params[k + 1].kind is not p.POSITIONAL_ONLY):
            parts.append("/")
    returns = sig.return_annotation
    tail = "" if returns is sig.empty or inspect.isclass(obj) else " -> " + (
        returns if isinstance(returns, str) else inspect.formatannotation(returns))
    one_line = f"{head}({', '.join(parts)}){tail}"
    if len(one_line) <= CODE_COLUMNS:
        return one_line
    return "\n".join([f"{head}(", *(f"    {part}," for part in parts), f"){tail}"])


def api_markdown() -> str:
    return "\n".join(_entry(path) for path in API)


def models_markdown() -> str:
    """One row per bundled model, every cell read from the model file's own metadata (``rbc.model``)."""
    import json

    import onnxruntime as ort

    from drive_server.serving.models_dir import bundled_models
    from drive_server.serving.settings import NO_GAIN, SERVING_KEY, Serving
    from drive_server.serving.smoothing import OFF

    lines = ["| model | network (parameters) | behavior, approach | camera rig | training samples | answer |",
             "|---|---|---|---|---|---|"]
    for path in bundled_models():
        meta = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).get_modelmeta()
        record = json.loads(meta.custom_metadata_map.get("rbc.model", "{}"))
        serving = Serving.from_json(meta.custom_metadata_map.get(SERVING_KEY))
        answer = []
        if str(record.get("mirror_average")).lower() == "true":
            answer.append("mirror-averaged")
        if str(record.get("output_scale", 1)) not in ("1.0", "1"):
            answer.append(f"times {record['output_scale']} in the graph")
        if serving.gain != NO_GAIN:
            answer.append(f"gain {serving.gain:g}")
        if serving.smoothing < OFF:
            answer.append(f"smoothed {serving.smoothing:g}")
        params = f"{int(record['parameters']):,}" if record.get("parameters") else "–"
        samples = f"{int(record['train_samples']):,}" if record.get("train_samples") else "–"
        lines.append(f"| `{path.name}` | {record.get('arch', '–')} ({params}) | {record.get('behavior', '–')}, "
                     f"{record.get('approach', '–')} | {record.get('camera_rig') or 'classic'} | {samples} | "
                     f"{', '.join(answer) or 'as trained'} |")
    return "\n".join(lines) + "\n"


def readme_markdown(readme: Path) -> str:
    """The README as a page of the site: links into ``docs/`` made relative, the repository's license kept."""
    return readme.read_text(encoding="utf-8").replace("](docs/", "](")


def on_page_markdown(markdown: str, page: Page | None = None, config: MkDocsConfig | None = None,
                     files: Files | None = None) -> str:
    """MkDocs hook: fill the generated sections of a page."""
    if README_MARKER in markdown:
        root = Path(config["config_file_path"]).parent if config is not None else Path.cwd()
        markdown = markdown.replace(README_MARKER, readme_markdown(root / "README.md"))
    if COMMANDS_MARKER in markdown:
        markdown = markdown.replace(COMMANDS_MARKER, commands_markdown())
    if API_MARKER in markdown:
        markdown = markdown.replace(API_MARKER, api_markdown())
    if MODELS_MARKER in markdown:
        markdown = markdown.replace(MODELS_MARKER, models_markdown())
    if "<!-- results " in markdown:
        from tools.results import fill

        markdown = fill(markdown)
    return markdown
