"""Fixtures of the CLI-package tests (the demo runs a real server with this small model)."""

from __future__ import annotations

import pytest

from realtime_core.avmodel import AvModel
from tests.speech import small_model


@pytest.fixture(scope="session")
def model() -> AvModel:
    return small_model()
