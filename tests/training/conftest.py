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


@pytest.fixture
def grid_copy(shared_data, tmp_path):
    """``grid_copy(ids, name="grid")``: a GRID-layout folder (``video/``, ``align/``) under the test's temporary
    folder holding copies of those GRID s1 sentences (a small corpus the commands read as they read GRID s1)."""
    import shutil

    s1 = shared_data / "video" / "grid_s1"

    def make(ids, name: str = "grid") -> Path:
        dest = tmp_path / name
        (dest / "video").mkdir(parents=True)
        (dest / "align").mkdir()
        for sid in ids:
            shutil.copy(s1 / "video" / f"{sid}.mp4", dest / "video")
            shutil.copy(s1 / "align" / f"{sid}.align", dest / "align")
        return dest

    return make
