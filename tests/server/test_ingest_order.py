"""Several sessions streaming at once into the ingest fast path (server.app.FacecastConnection,
LiveSession.feed_now), over loopback, with controls pipelined between their blocks: each session gets
the frames a sans-I/O Session gives when fed the same blocks with the controls applied between them.
A change that moves when a block is pushed (queued to the end of the loop turn, say) must keep this."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

from clients.client import IngestClient, ViewerClient
from server.session import Session, SessionConfig
from tests.live_server import running
from tests.speech import speechlike
from wire import protocol as P

# A real server and clients over loopback sockets.
pytestmark = pytest.mark.system

RATE = 16000
# Block sizes in samples: 20 ms blocks, and larger ones (a fair slice is 1600, so 4000 takes the
# handler's path between fast-path blocks).
SIZES = [320, 320, 960, 320, 4000, 320]


def _blocks(pcm: np.ndarray, shift: int) -> list[np.ndarray]:
    sizes = SIZES[shift:] + SIZES[:shift]
    blocks, i, k = [], 0, 0
    while i < len(pcm):
        n = sizes[k % len(sizes)]
        blocks.append(pcm[i : i + n])
        i, k = i + n, k + 1
    return blocks


def _reference(model, blocks: list[np.ndarray], controls: dict[int, dict]) -> np.ndarray:
    """(frames, 4) float32 parameters of a sans-I/O Session fed the blocks one by one, each control
    applied before the block of its index, then flushed."""
    s = Session(model, config=SessionConfig(sample_rate_hz=RATE, sample_format="pcm_s16le"))
    frames = []
    for k, block in enumerate(blocks):
        if k in controls:
            s.apply_control({"type": "control", "gain": controls[k]})
        frames += s.push_bytes(block.astype("<i2").tobytes()).frames
    frames += s.flush().frames
    return np.array([np.frombuffer(f.payload(P.KIND_PARAMS, P.ENC_FLOAT32)[0], "<f4") for f in frames])


def test_sessions_streaming_together_keep_their_order_and_frames(model):
    clips = [(speechlike(1.5, RATE, seed=20 + i) * 32767).astype(np.int16) for i in range(3)]
    blocks = [_blocks(clip, i) for i, clip in enumerate(clips)]
    # Each session's controls between different blocks (one has none), sent without waiting for the ack.
    controls = [
        {3: {"lip_stretch": 2.0}, 4: {"mouth_open": 0.5}, 18: {"lip_stretch": 0.5}},
        {1: {"mouth_open": 2.0}, 12: {"upper_lip_raise": 0.3}, 13: {"mouth_open": 1.0}},
        {},
    ]

    async def stream(ing: IngestClient, blocks: list[np.ndarray], controls: dict[int, dict]) -> None:
        for k, block in enumerate(blocks):
            if k in controls:
                await ing.ws.send(json.dumps({"type": "control", "gain": controls[k]}))
            await ing.send(block)
            if k + 1 not in controls:
                # A short gap (faster than real time still): the server keeps up, so blocks take the
                # fast path instead of piling up behind the handler's queue, and the three sessions'
                # blocks arrive together. No gap before a control: it arrives right behind the block
                # before it (in the same read), where an order bug would let one overtake the other.
                await asyncio.sleep(0.004)
        for _ in controls:
            assert json.loads(await ing.ws.recv())["type"] == "ack"

    assert all(max(c, default=0) < len(b) for b, c in zip(blocks, controls))  # every control is sent

    async def main():
        async with running(model) as srv:
            ingests = [IngestClient(srv.url, session=f"b{i}", sample_rate_hz=RATE) for i in range(3)]
            for ing in ingests:
                await ing.__aenter__()
            viewers = [ViewerClient(srv.url, session=f"b{i}", audio=False) for i in range(3)]
            for v in viewers:
                await v.__aenter__()
            tasks = [asyncio.ensure_future(v.collect()) for v in viewers]
            # Not real time: blocks of all three sessions arrive together, several per loop turn.
            await asyncio.gather(*(stream(ing, b, c) for ing, b, c in zip(ingests, blocks, controls)))
            ended = [await ing.end() for ing in ingests]
            got = await asyncio.gather(*tasks)
            for c in (*viewers, *ingests):
                await c.__aexit__(None, None, None)
            return ended, got

    ended, got = asyncio.run(main())
    for b, c, end, rec in zip(blocks, controls, ended, got):
        want = _reference(model, b, c)
        assert end["frames"] == len(want) == len(rec.frames) > 40
        assert [m.index for m in rec.frames] == list(range(len(want)))
        np.testing.assert_array_equal(rec.values(), want)
    plain = _reference(model, blocks[0], {})
    assert not np.array_equal(plain, _reference(model, blocks[0], controls[0]))  # the controls change frames
