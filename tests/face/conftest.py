"""Shared fixtures for realtime_core.face tests: the path to the shared reference data."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

DATA = Path(os.environ.get("FACECAST_SHARED_DATA", Path(__file__).resolve().parents[2] / ".." / "shared" / "data"))


@pytest.fixture
def shared_data() -> Path:
    """``../shared/data`` relative to the repository root; skips when absent."""
    if not DATA.is_dir():
        pytest.skip(f"shared reference data not found: {DATA.resolve()}")
    return DATA
