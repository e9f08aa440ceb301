"""CI runs the type checker (mypy, pinned) between the linter and the tests; protocol and drive_server strictly."""

from __future__ import annotations

import tomllib

from helpers_server import REPO

#: The packages checked strictly (the deployment code), the rest with mypy's defaults.
STRICT_PACKAGES = ("protocol", "drive_server")

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


def test_protocol_and_drive_server_are_strict_and_the_rest_is_not():
    """``strict = true`` in an override section turns --strict on for every module: the flags are spelled out."""
    config = _mypy()
    assert "strict" not in config and not any("strict" in o for o in config["overrides"])
    (strict,) = [o for o in config["overrides"] if STRICT_FLAGS & set(o)]
    assert sorted(strict["module"]) == sorted(m for p in STRICT_PACKAGES for m in (p, f"{p}.*"))
    assert {flag for flag in STRICT_FLAGS if strict.get(flag) is True} == STRICT_FLAGS
    assert strict["implicit_reexport"] is False and config["warn_redundant_casts"] is True
    assert not [k for k in config if k in STRICT_FLAGS or k == "implicit_reexport"]
