"""Shared fixtures of the training-data tests: the shared reference data and espeak-ng."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("FACECAST_SHARED_DATA") or REPO.parent / "shared" / "data")
"""``$FACECAST_SHARED_DATA`` (a checkout in a worktree elsewhere) or ``../shared/data``."""


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


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` next to the repository; tests that need it skip when it is absent."""
    if not SHARED.is_dir():
        pytest.skip(f"reference data not found at {SHARED} (../shared/data beside the repository)")
    return SHARED


@pytest.fixture(scope="session")
def espeak():
    """The shared espeak-ng synthesizer (real libespeak-ng.so.1)."""
    from training.errors import SynthesisError
    from assets.espeak import synthesizer

    try:
        return synthesizer()
    except SynthesisError as exc:
        pytest.skip(f"espeak-ng library unavailable: {exc}")


@pytest.fixture(scope="session")
def ffmpeg() -> str:
    path = shutil.which("ffmpeg")
    if path is None:
        pytest.skip("ffmpeg is not installed (apt package ffmpeg)")
    return path


