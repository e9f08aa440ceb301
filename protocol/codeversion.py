"""The version of a computation: its code, derived from what it imports, and its data, as digests.

A journal or cache that reuses a result must be keyed on everything the result depends on. A hand-kept list of
folders goes stale the day a scorer imports a module outside it, so the code is found instead: from the entry
modules of a computation every import of the project's own packages (top level and inside functions, not under
``if TYPE_CHECKING:``) is followed, each package's ``__init__`` with it, and the closure's sources are hashed
together with the data files beside them (a package folder's non-Python files, e.g. a manifest or a track) and the
versions of the third-party distributions the closure imports. Comments, blank lines and docstrings do not count:
a change to them cannot change a figure, and an expensive result (a fold model) is not redone for it.
Standard library only, so every layer may use it.
"""

from __future__ import annotations

import ast
import hashlib
import io
import sys
import tokenize
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import metadata
from pathlib import Path

#: The project's own packages: the only imports followed (the rest count by their distribution's version).
PACKAGES = ("protocol", "drive_server", "models", "tools")
ROOT = Path(__file__).resolve().parents[1]
#: Files in a package folder that are not data a computation reads: sources, docs, a web page's assets.
_NOT_DATA = {".py", ".pyc", ".pyo", ".md", ".html", ".css", ".js"}


@dataclass(frozen=True)
class CodeVersion:
    """``digest`` names the whole; ``files`` (path under the root -> digest) and ``libraries`` (distribution ->
    version) say what went into it."""

    digest: str
    files: Mapping[str, str] = field(default_factory=dict)
    libraries: Mapping[str, str] = field(default_factory=dict)


def code_version(*entries: str, root: Path = ROOT) -> CodeVersion:
    """The version of the code that the modules ``entries`` (dotted names under ``root``) run; cached per process."""
    return _code_version(tuple(sorted(set(entries))), Path(root).resolve())


def code_digest(*entries: str, root: Path = ROOT) -> str:
    """:func:`code_version`'s digest alone: what a cache key holds."""
    return code_version(*entries, root=root).digest


def clear_cache() -> None:
    """Forget the versions worked out so far (a test that edits a scratch tree between two calls)."""
    for cached in (_code_version, _index, _closure):
        cached.cache_clear()


def module_closure(entries: Iterable[str], root: Path = ROOT) -> list[str]:
    """Every module of the project that ``entries`` import, directly or not, with the packages they sit in."""
    return sorted(_closure(tuple(sorted(set(entries))), Path(root).resolve())[0])


@lru_cache(maxsize=64)
def _code_version(entries: tuple[str, ...], root: Path) -> CodeVersion:
    modules, outside = _closure(entries, root)
    index = _index(root)
    paths = {index[m] for m in modules}
    for folder in sorted({p.parent for p in paths}):
        paths.update(_data_files(folder))
    files = {p.relative_to(root).as_posix(): _file_digest(p) for p in sorted(paths)}
    libraries = _library_versions(outside)
    whole = hashlib.sha256()
    for name, digest in sorted(files.items()) + sorted(libraries.items()):
        whole.update(f"{name}\0{digest}\0".encode())
    return CodeVersion(f"code {whole.hexdigest()[:16]}", files, libraries)


def data_digest(paths: Iterable[Path | str]) -> str:
    """The data a computation reads from ``paths`` (files or folders): a driving log's CSV by its content, every
    other file (the frames, thousands of them) by its name and size: a re-recorded or re-cut recording changes it,
    and reading every image of a data set to make a key is not needed for that."""
    digest = hashlib.sha256()
    for given in paths:
        top = Path(given)
        files = sorted(p for p in top.rglob("*") if p.is_file()) if top.is_dir() else [top]
        digest.update(f"{top.name}\0".encode())
        for path in files:
            name = path.relative_to(top).as_posix() if top.is_dir() else path.name
            if path.suffix.lower() == ".csv" or not top.is_dir():
                digest.update(f"{name}\0".encode() + hashlib.sha256(path.read_bytes()).digest())
            else:
                digest.update(f"{name}\0{path.stat().st_size}\0".encode())
    return digest.hexdigest()[:16]


@lru_cache(maxsize=8)
def _index(root: Path) -> dict[str, Path]:
    """Dotted module name -> source file, for the project's packages under ``root``."""
    out: dict[str, Path] = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


@lru_cache(maxsize=64)
def _closure(entries: tuple[str, ...], root: Path) -> tuple[frozenset[str], frozenset[str]]:
    """(the project's modules reached from ``entries``, the top-level names of other imports outside the stdlib)."""
    index = _index(root)
    missing = [e for e in entries if e not in index]
    if missing:
        raise ValueError(f"no module {', '.join(missing)} under {root}")
    seen: set[str] = set()
    outside: set[str] = set()
    todo = [".".join(e.split(".")[:i]) for e in entries for i in range(1, e.count(".") + 2)]  # with its packages
    while todo:
        name = todo.pop()
        if name in seen or name not in index:  # a folder without __init__ runs nothing
            continue
        seen.add(name)
        for imported in _imports(name, index[name]):
            top = imported.split(".")[0]
            if top in PACKAGES:
                parts = imported.split(".")
                # importing a.b.c runs a, a.b and a.b.c; a name imported from a module is no module itself
                todo += [m for m in (".".join(parts[:i]) for i in range(1, len(parts) + 1)) if m in index]
            elif top not in sys.stdlib_module_names and top != "__future__":
                outside.add(top)
    return frozenset(seen), frozenset(outside)


def _imports(name: str, path: Path) -> set[str]:
    """The dotted names a module imports, anywhere but under ``if TYPE_CHECKING:`` (relative ones resolved)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    todo: list[ast.AST] = [ast.parse(path.read_bytes(), filename=str(path))]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            todo += node.orelse
            continue
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([base] if base else [])])
            found.add(base)
            found.update(f"{base}.{a.name}" for a in node.names)
        todo += ast.iter_child_nodes(node)
    return {f for f in found if f}


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _data_files(folder: Path) -> list[Path]:
    """A package folder's data: its non-Python files, and those of sub-folders that are no packages."""
    out = []
    for path in folder.iterdir():
        if path.name.startswith(".") or path.name == "__pycache__":
            continue
        if path.is_dir():
            if not (path / "__init__.py").exists():
                out += _data_files(path)
        elif path.suffix not in _NOT_DATA:
            out.append(path)
    return out


def _file_digest(path: Path) -> str:
    data = path.read_bytes()
    if path.suffix == ".py":
        data = _normalised_source(data)
    return hashlib.sha256(data).hexdigest()[:16]


def _normalised_source(source: bytes) -> bytes:
    """The tokens that make the program: no comments, blank lines or docstrings (a change to them changes no
    result). A file that does not tokenize is taken as it is."""
    try:
        docstrings = {(n.body[0].lineno, n.body[0].col_offset) for n in ast.walk(ast.parse(source))
                      if isinstance(n, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
                      and n.body and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)
                      and isinstance(n.body[0].value.value, str)}
        out = []
        for tok in tokenize.tokenize(io.BytesIO(source).readline):
            if tok.type in (tokenize.COMMENT, tokenize.NL, tokenize.ENCODING):
                continue
            if tok.type == tokenize.STRING and tok.start in docstrings:
                continue
            out.append(tokenize.tok_name[tok.type] if tok.type in (tokenize.INDENT, tokenize.DEDENT) else tok.string)
        return "\0".join(out).encode()
    except (SyntaxError, tokenize.TokenError, ValueError):
        return source


def _library_versions(tops: Iterable[str]) -> dict[str, str]:
    """The installed version of each distribution that provides one of ``tops`` (``absent``: not installed)."""
    providers = _providers()
    out: dict[str, str] = {}
    for top in tops:
        for dist in providers.get(top, [top]):
            try:
                out[dist] = metadata.version(dist)
            except metadata.PackageNotFoundError:
                out[dist] = "absent"
    return out


@lru_cache(maxsize=1)
def _providers() -> Mapping[str, list[str]]:
    return metadata.packages_distributions()
