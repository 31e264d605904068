"""Fixtures of the training-data tests: a private face-track cache."""

from __future__ import annotations

import os
from pathlib import Path

import pytest


@pytest.fixture(scope="session", autouse=True)
def private_face_cache(tmp_path_factory):
    """Face-track extraction in tests measures for real: a private cache, never the user's."""
    old = os.environ.get("FACECAST_CACHE")
    os.environ["FACECAST_CACHE"] = str(tmp_path_factory.mktemp("facecast-cache"))
    yield Path(os.environ["FACECAST_CACHE"])
    if old is None:
        os.environ.pop("FACECAST_CACHE", None)
    else:
        os.environ["FACECAST_CACHE"] = old
