"""Fixtures of the head tests: third-party heads from ../shared/data (or $FACECAST_SHARED_DATA)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.prerequisites import require_data


@pytest.fixture(scope="session")
def shared_lps() -> Path:
    """The Lee Perry-Smith head scan (glTF)."""
    return require_data("heads/lee-perry-smith/LeePerrySmith.glb")
