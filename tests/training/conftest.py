"""Shared fixtures of the training-data tests: the shared reference data and espeak-ng."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared" / "data"


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
    from training.espeak import synthesizer

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


