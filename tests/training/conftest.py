"""Fixtures of the training-data tests: the espeak-ng synthesizer."""

from __future__ import annotations

import pytest

from tests.prerequisites import missing


@pytest.fixture(scope="session")
def espeak():
    """The shared espeak-ng synthesizer (real libespeak-ng.so.1)."""
    from training.errors import SynthesisError
    from training.espeak import synthesizer

    try:
        return synthesizer()
    except SynthesisError as exc:
        missing(f"espeak-ng library unavailable (apt package libespeak-ng1): {exc}")
