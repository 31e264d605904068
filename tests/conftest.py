"""Shared test fixtures: the location of ../shared/data and a helper that skips clearly."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("FACECAST_SHARED_DATA") or REPO.parent / "shared" / "data")


def shared_file(rel: str) -> Path:
    """Path of a file under ../shared/data, or skip the test naming what is missing."""
    path = SHARED_DATA / rel
    if not path.exists():
        pytest.skip(f"third-party test data not found: {path} (expected ../shared/data beside the repository)")
    return path
