"""CI runs the type checker (mypy, pinned) between the linter and the tests; protocol is checked strictly."""

from __future__ import annotations

import tomllib

from helpers_server import REPO

#: What ``mypy --strict`` turns on that a per-module section can hold (warn_redundant_casts is global only).
STRICT_FLAGS = {"disallow_any_generics", "disallow_subclassing_any", "disallow_untyped_calls", "disallow_untyped_defs",
                "disallow_incomplete_defs", "check_untyped_defs", "disallow_untyped_decorators", "warn_unused_ignores",
                "warn_return_any", "strict_equality", "extra_checks"}


def _mypy() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["mypy"]


def test_ci_runs_mypy_after_ruff_and_before_the_tests():
    ci = [line.split("#")[0].strip() for line in (REPO / ".ci" / "run").read_text(encoding="utf-8").splitlines()]
    assert ci.index("ruff check .") < ci.index("mypy") < ci.index("python -m pytest -q")


def test_mypy_is_pinned_and_checks_every_package():
    extras = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    assert [d for d in extras["dev"] if d.startswith("mypy==")], "pin mypy: a new release's checks must not break CI"
    assert set(_mypy()["files"]) == {"protocol", "drive_server", "models", "tools"}


def test_protocol_is_strict_and_the_rest_is_not():
    """``strict = true`` in an override section turns --strict on for every module: the flags are spelled out."""
    config = _mypy()
    assert "strict" not in config and not any("strict" in o for o in config["overrides"])
    (protocol,) = [o for o in config["overrides"] if "protocol" in o["module"]]
    assert {flag for flag in STRICT_FLAGS if protocol.get(flag) is True} == STRICT_FLAGS
    assert protocol["implicit_reexport"] is False and config["warn_redundant_casts"] is True
    assert not [k for k in config if k in STRICT_FLAGS or k == "implicit_reexport"]
