"""Fixtures of the CLI-package tests (the demo runs a real server with this small model)."""

from __future__ import annotations

from pathlib import Path

import pytest

from realtime_core.avmodel import AvModel
from tests.speech import small_model


@pytest.fixture(scope="session")
def model() -> AvModel:
    return small_model()


@pytest.fixture
def own_cache(tmp_path_factory, monkeypatch, builtin_head) -> Path:
    """FACECAST_CACHE set to a cache of the test's own (the shared one is written by other runs), holding only the
    built-in head and its rig (links to the user's cache's files): a mesh's rig is made afresh in it."""
    from assets.heads.cache import cache_dir

    user = cache_dir()
    cache = tmp_path_factory.mktemp("cache")
    for built in user.glob("builtin_*.npz"):
        (cache / built.name).symlink_to(built)
    monkeypatch.setenv("FACECAST_CACHE", str(cache))
    return cache
