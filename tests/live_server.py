"""A real facecast server on loopback in a background thread, for the viewer and recording tests
(fixture ``live`` in tests/clients/conftest.py; also used by scripts/screenshots.py).

The server runs the way ``facecast serve`` runs it (same class, its own event loop) with a small
model whose mouth motion stays in the parameters' typical ranges, the built-in head, the browser
viewer's files and three.js from node_modules. Tests talk to it over real sockets only; coroutines
(ingest clients) are run on the server's loop with :meth:`LiveServer.call`.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from pathlib import Path
from typing import Any

import numpy as np

from realtime_core.avmodel import AvModel
from tests.speech import speechlike

REPO = Path(__file__).resolve().parents[1]


@contextlib.asynccontextmanager
async def running(model: AvModel, head=None, **config):
    """A FacecastServer started on this event loop (free port, ``ServerConfig(**config)``), stopped on exit."""
    from server.app import FacecastServer
    from server.config import ServerConfig

    srv = FacecastServer(model, head=head, config=ServerConfig(port=0, **config))
    await srv.start()
    try:
        yield srv
    finally:
        await srv.stop()


class LiveServer:
    """A started FacecastServer on 127.0.0.1 (free port) served from a daemon thread's loop."""

    def __init__(self, model: AvModel, head, *, port: int = 0, **settings: Any) -> None:
        """settings: other ServerConfig fields (e.g. max_message_bytes), the defaults otherwise."""
        from server.app import FacecastServer
        from server.config import ServerConfig
        from server.eventloop import loop_factory

        nm = REPO / "node_modules"
        self.config = ServerConfig(
            port=port,
            web_root=REPO / "clients" / "web",
            node_modules=nm if nm.is_dir() else None,
            close_timeout_s=0.5,
            **settings,
        )
        self.server = FacecastServer(model, head=head, config=self.config)
        self.loop = loop_factory(self.config.event_loop)()  # the loop `facecast serve` would run it on
        self.thread = threading.Thread(target=self.loop.run_forever, name="facecast-test-server", daemon=True)
        self.thread.start()
        self.call(self.server.start())
        self.port = self.server.port
        self.url = f"http://127.0.0.1:{self.port}"

    def call(self, coro, timeout: float = 60.0):
        """Run a coroutine on the server's loop and wait for its result."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def submit(self, coro):
        """Start a coroutine on the server's loop; returns its concurrent.futures.Future."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop)

    def stop(self) -> None:
        self.call(self.server.stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        self.loop.close()


async def stream_session(
    url: str,
    name: str,
    seconds: float,
    *,
    realtime: bool = True,
    seed: int = 0,
    stop: asyncio.Event | None = None,
    samples: np.ndarray | None = None,
) -> dict:
    """Ingest ``seconds`` of speech-like 16 kHz audio (or ``samples``, (n,) float32 at 16 kHz) as
    session ``name`` (in real time unless told otherwise), ending early when ``stop`` is set; returns
    the server's ``ended`` reply."""
    from assets.pacing import paced_blocks
    from clients.client import IngestClient

    x = speechlike(seconds, 16000, seed=seed) if samples is None else samples
    async with IngestClient(url, session=name, sample_rate_hz=16000) as ing:
        async for _, block in paced_blocks(x, 16000, block_s=0.02, realtime=realtime):  # 20 ms blocks
            if stop is not None and stop.is_set():
                break
            await ing.send(block)
        return await ing.end()
