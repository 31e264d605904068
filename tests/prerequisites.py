"""Prerequisites of tests: a missing tool, module or data set skips a test (with the reason, printed by
``-rs``) outside CI and FAILS it in CI (environment ``CI=true``, as .ci/run runs): CI installs
everything (scripts/setup.sh), so a skip there would hide a broken set-up."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import NoReturn

import pytest

from assets.shared import shared_data_root

REPO = Path(__file__).resolve().parents[1]
# ../shared/data beside the checkout; FACECAST_SHARED_DATA overrides it (e.g. for a git worktree elsewhere).
SHARED_DATA = shared_data_root()


def in_ci() -> bool:
    """True under CI (``CI=true``, as .ci/run is run): missing prerequisites fail instead of skipping."""
    return os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


def missing(reason: str) -> NoReturn:
    """Stop the test because a prerequisite is missing: a failure in CI, a skip (with the reason) elsewhere."""
    if in_ci():
        pytest.fail(f"missing in CI: {reason}", pytrace=False)
    pytest.skip(reason)


def require(condition: object, reason: str) -> None:
    """:func:`missing` unless ``condition`` holds."""
    if not condition:
        missing(reason)


def require_tool(name: str, hint: str = "") -> str:
    """The path of executable ``name`` on PATH, or :func:`missing` (``hint``: how to install it)."""
    path = shutil.which(name)
    if path is None:
        missing(f"{name} is not installed" + (f" ({hint})" if hint else ""))
    return path


def require_data(rel: str | Path) -> Path:
    """The path of ``rel`` under ../shared/data (or an absolute path), or :func:`missing`."""
    path = Path(rel) if Path(rel).is_absolute() else SHARED_DATA / rel
    if not path.exists():
        missing(f"test data not found: {path} (expected ../shared/data beside the repository)")
    return path


def require_module(name: str, hint: str = "") -> object:
    """``pytest.importorskip`` that fails in CI instead of skipping."""
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError as exc:
        missing(f"Python module {name} unavailable: {exc}" + (f" ({hint})" if hint else ""))
