"""Fixtures of the server tests: a small random model (also saved to disk), test speech as WAV files; every
test's ``asyncio.run`` on the loop ``facecast serve`` runs on."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from realtime_core.avmodel import AvModel
from tests.speech import small_model, speechlike


@pytest.fixture(autouse=True)
def server_event_loop():
    """Most tests run a server inside their own ``asyncio.run``: make that the loop the server runs on in
    production (``ServerConfig().event_loop``, uvloop on Linux), not the standard one. Servers in child
    processes pick theirs from their configuration."""
    from server.eventloop import DEFAULT_EVENT_LOOP

    if DEFAULT_EVENT_LOOP != "uvloop":
        yield
        return
    import uvloop

    old = asyncio.get_event_loop_policy()
    asyncio.set_event_loop_policy(uvloop.EventLoopPolicy())
    try:
        yield
    finally:
        asyncio.set_event_loop_policy(old)


@pytest.fixture(scope="session")
def model() -> AvModel:
    return small_model()


@pytest.fixture(scope="session")
def model_path(tmp_path_factory, model) -> Path:
    from assets.modelfile import save_model

    return save_model(tmp_path_factory.mktemp("model") / "small.npz", model)


@pytest.fixture(scope="session")
def wav16k(tmp_path_factory) -> Path:
    """2 s of speech-like audio at 16 kHz as a pcm_s16le WAV file."""
    from assets.audio import write_wav

    path = tmp_path_factory.mktemp("audio") / "speech16k.wav"
    write_wav(path, speechlike(2.0, 16000), 16000)
    return path


@pytest.fixture(scope="session")
def wav48k(tmp_path_factory) -> Path:
    """1.5 s of speech-like audio at 48 kHz."""
    from assets.audio import write_wav

    path = tmp_path_factory.mktemp("audio") / "speech48k.wav"
    write_wav(path, speechlike(1.5, 48000, seed=1), 48000)
    return path
