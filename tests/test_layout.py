"""The layout's rules: who may import whom, one decode for serving and training, one dispatcher.

These are the architecture written down as tests, so a later change cannot quietly undo it.
"""

from __future__ import annotations

import ast
import base64
import sys
from pathlib import Path

import numpy as np
import pytest

from drive_server.contract import NVIDIA_CONTRACT, PAPER_CONTRACT
from drive_server.preprocess import jpeg_reduction, preprocess, to_input_tensor
from protocol import decode_image
from protocol.datalog import read_log
from tools.cli import SUBCOMMANDS, find_subcommand, load, main, subcommand_parser

REPO = Path(__file__).resolve().parents[1]
OURS = ("protocol", "drive_server", "models", "tools")
STDLIB = sys.stdlib_module_names
SAMPLE = REPO / "tests" / "data" / "udacity-sample"


def _modules() -> dict[str, Path]:
    out = {}
    for package in OURS:
        for path in sorted((REPO / package).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()


def _imports(path: Path) -> set[str]:
    """Every module imported anywhere in the file (top level and inside functions)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{a.name}" for a in node.names
                         if f"{node.module}.{a.name}" in MODULES)
    return found


def _violations(prefix: str, forbidden: tuple[str, ...]) -> list[str]:
    return [f"{name} imports {imp}" for name, path in MODULES.items() if name == prefix or name.startswith(prefix + ".")
            for imp in sorted(_imports(path)) if imp.split(".")[0] in forbidden or imp in forbidden]


def test_protocol_imports_nothing_of_ours():
    assert _violations("protocol", ("drive_server", "models", "tools")) == []


def test_the_log_format_and_facts_are_stdlib_only():
    for name in ("protocol.datalog", "protocol.datalog_writer", "protocol.facts", "protocol.errors"):
        imports = _imports(MODULES[name])
        outside = [i for i in imports if i.split(".")[0] not in STDLIB and not i.startswith("protocol.")]
        assert outside == [], name


def test_drive_server_imports_neither_models_nor_torch_nor_tools():
    assert _violations("drive_server", ("models", "tools", "torch", "onnx", "matplotlib")) == []


def test_the_simulator_never_imports_models():
    assert _violations("tools.sim", ("models", "torch")) == []


def test_the_simulators_sub_packages_import_only_along_their_arrows():
    from tools.sim import ALLOWED_IMPORTS

    packages = {p.name for p in (REPO / "tools" / "sim").iterdir() if (p / "__init__.py").exists()}
    assert packages == set(ALLOWED_IMPORTS), "every sub-package has its arrows in tools.sim.ALLOWED_IMPORTS"
    wrong = []
    for name, path in MODULES.items():
        parts = name.split(".")
        if parts[:2] != ["tools", "sim"] or len(parts) < 3 or parts[2] not in ALLOWED_IMPORTS:
            continue
        for imp in _imports(path):
            target = imp.split(".")
            outside = target[:2] == ["tools", "sim"] and len(target) > 2 and target[2] != parts[2]
            if outside and target[2] not in ALLOWED_IMPORTS[parts[2]]:
                wrong.append(f"{name} imports {imp}")
    assert wrong == []


def test_no_module_sits_loose_in_the_simulator_and_no_room_is_crowded():
    sim = REPO / "tools" / "sim"
    assert sorted(p.name for p in sim.glob("*.py")) == ["__init__.py"]
    for package in (p for p in sim.iterdir() if (p / "__init__.py").exists()):
        assert len([m for m in package.glob("*.py") if m.name != "__init__.py"]) <= 15, package.name


def test_models_never_import_tools():
    assert _violations("models", ("tools",)) == []


def test_command_modules_hold_no_library_code_and_do_not_import_each_other():
    for name, path in MODULES.items():
        if not name.startswith("tools.commands.") or name == "tools.commands":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        public = {n.name for n in tree.body if isinstance(n, ast.FunctionDef) and not n.name.startswith("_")}
        assert public == {"add_arguments", "run"}, name
        assert not [n for n in tree.body if isinstance(n, ast.ClassDef)], f"{name} defines a class"
        assert not [i for i in _imports(path) if i.startswith("tools.commands.")], f"{name} imports a command"


def test_no_import_cycles():
    graph = {name: {i for i in _imports(path) if i in MODULES and i != name} for name, path in MODULES.items()}
    # a package's __init__ importing its own submodules is how re-exports work, not a cycle of jobs
    graph = {n: {d for d in deps if not (d.startswith(n + ".") and MODULES[n].name == "__init__.py")}
             for n, deps in graph.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    assert cycles == []


# --------------------------------------------------------------------------- one decode for serving and training


@pytest.mark.parametrize("contract", [PAPER_CONTRACT, NVIDIA_CONTRACT], ids=["paper", "nvidia"])
def test_serving_and_training_decode_a_frame_identically(contract):
    from models.data.framecache import build_cache, load_frame

    samples, _ = read_log(SAMPLE)
    samples = samples[:6]
    reduce = jpeg_reduction(contract)
    cache = build_cache(samples, contract, cameras=("center",), workers=1)
    for i, s in enumerate(samples):
        served = decode_image(base64.b64encode(s.center.read_bytes()).decode("ascii"), reduce)  # telemetry path
        assert np.array_equal(served, load_frame(s.center, reduce))  # training path, same pixels
        assert np.array_equal(preprocess(served, contract), to_input_tensor(cache.frames[0, i], contract))


# --------------------------------------------------------------------------- the rbc dispatcher


@pytest.mark.parametrize(("argv", "expected"), [
    (["train", "--data", "D", "--out", "sim"], "train"),
    (["eval", "--out", "demo"], "eval"),
    (["compare", "--eval", "eval", "--out", "t.md"], "compare"),
    (["-v", "sim", "--autopilot"], "sim"),
    (["--verbose", "collect", "--out", "train"], "collect"),
])
def test_the_first_positional_argument_is_the_subcommand(argv, expected):
    cmd, index = find_subcommand(argv)
    assert cmd is not None and cmd.name == expected and argv[index] == expected


def test_flags_named_like_other_subcommands_parse_for_the_chosen_one():
    cmd, index = find_subcommand(["eval", "--out", "demo", "--behavior", "rigorous"])
    args = subcommand_parser(cmd, load(cmd)).parse_args(["--out", "demo", "--behavior", "rigorous"])
    assert str(args.out) == "demo" and args.behavior == "rigorous"


@pytest.mark.parametrize("argv", [["eval", "--out", "demo", "--behavior", "nope"],
                                  ["collect", "--out", "sim", "--behavior", "nope"]])
def test_main_parses_with_the_named_subcommand_even_when_values_name_others(argv, capsys):
    """Was: the first subcommand NAME found anywhere in argv won (``--out demo`` chose ``rbc demo``)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert f"rbc {argv[0]}: error:" in capsys.readouterr().err


def test_every_subcommand_module_loads_and_builds_its_parser():
    for cmd in SUBCOMMANDS:
        if cmd.extra:
            pytest.importorskip("torch" if cmd.extra == "train" else "matplotlib")
        module = load(cmd)
        assert callable(module.run)
        assert subcommand_parser(cmd, module).prog == f"rbc {cmd.name}"


def test_unknown_subcommand_and_no_subcommand_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["nope"])
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
    assert main([]) == 2


def test_subcommand_help_is_the_subcommands_own(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["sim", "--help"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.startswith("usage: rbc sim")


def test_a_typo_in_a_flag_shows_the_subcommands_usage(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["sim", "--autopilot", "--tarck", "lake"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: rbc sim") and "--tarck" in err
