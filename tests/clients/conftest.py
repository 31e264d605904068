"""Fixtures of the clients tests: a real facecast server on loopback (see :mod:`tests.live_server`)
serving a model whose mouth motion stays in the parameters' typical ranges and the built-in head."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from realtime_core.avmodel import AvModel
from tests.live_server import LiveServer
from tests.speech import plausible_model


@pytest.fixture(scope="session")
def model() -> AvModel:
    return plausible_model()


@pytest.fixture()
def live(model, head) -> Iterator[LiveServer]:
    """A started server on a free loopback port, stopped after the test."""
    srv = LiveServer(model, head)
    try:
        yield srv
    finally:
        srv.stop()
