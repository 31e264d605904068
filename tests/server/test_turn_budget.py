"""A per-turn budget under overload, over loopback: a connection with a large backlog of buffered
blocks is served a bounded share of audio per loop turn (other tasks and /health run in between),
and its frames stay the ones the session computes fed whole, in order."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from clients.client import IngestClient, ViewerClient, http_get
from server.live import FAIR_SLICE_S
from server.session import Session, SessionConfig
from tests.live_server import running
from tests.speech import speechlike

# A real server and clients over loopback sockets.
pytestmark = pytest.mark.system


def test_a_backlog_is_served_a_bounded_share_per_loop_turn(model):
    rate, block = 16000, 320  # 20 ms blocks
    pcm = (speechlike(20.0, rate, seed=4) * 32767).astype(np.int16)
    blocks = [pcm[i : i + block].astype("<i2").tobytes() for i in range(0, len(pcm), block)]

    async def main():
        # A burst allowance longer than the audio: the pacer never waits, so only the budget yields.
        async with running(model, ingest_burst_s=600.0) as srv:
            async with IngestClient(srv.url, session="b", sample_rate_hz=rate) as ing:
                async with ViewerClient(srv.url, session="b", audio=False) as view:
                    collected = asyncio.ensure_future(view.collect())
                    core = srv.sessions["b"].session.core
                    seen: list[int] = []
                    done = asyncio.Event()

                    async def ticker() -> None:  # runs once per loop turn
                        while not done.is_set():
                            seen.append(core.frames_out)
                            await asyncio.sleep(0)

                    tick = asyncio.ensure_future(ticker())
                    assert ing.ws is not None
                    for b in blocks:  # the whole backlog at once: the socket delivers it in large reads
                        await ing.ws.send(b)
                    status, _ = await http_get(srv.url, "/health")
                    health_at = core.frames_out
                    ended = await ing.end()
                    done.set()
                    await tick
                got = await collected
        return ended, got, seen, status, health_at

    ended, got, seen, status, health_at = asyncio.run(main())
    s = Session(model, config=SessionConfig(sample_rate_hz=rate, sample_format="pcm_s16le"))
    want = np.concatenate([f.params for f in s.push_bytes(pcm.tobytes()).frames + s.flush().frames]).reshape(-1, 4)
    assert ended["frames"] == len(want) == len(got.frames) > 500
    np.testing.assert_array_equal(got.values(), want.astype(np.float32))  # every frame, in order
    # Between two turns of another task, at most the sink's share and the handler's share (each
    # FAIR_SLICE_S plus the block that crossed it) were processed: never the whole backlog.
    per_turn = np.diff(seen).max()
    assert per_turn <= int(np.ceil(2 * (FAIR_SLICE_S + block / rate) * 30)) + 1
    assert len(seen) > len(want) / per_turn / 2  # the ticker really ran all along
    assert status == 200 and health_at < len(want) - 30  # /health answered while the backlog was being worked off
