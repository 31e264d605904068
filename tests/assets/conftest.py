"""Fixtures for the assets tests: third-party heads from ../shared/data (FACECAST_SHARED_DATA)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

DATA = Path(os.environ.get("FACECAST_SHARED_DATA", Path(__file__).resolve().parents[2].parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_lps() -> Path:
    p = DATA / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    if not p.is_file():
        if os.environ.get("CI") == "true":
            pytest.fail(f"shared test data missing in CI: {p}")
        pytest.skip(f"shared reference data not found: {p}")
    return p
