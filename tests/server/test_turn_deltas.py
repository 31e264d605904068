"""Vertex deltas computed once per loop turn (server.live.TurnDeltas), over loopback: several sessions
streaming at once give each delta viewer the bytes the per-frame path gives, in order, with every
frame, while the server computes the deltas of several frames per turn."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

from clients.client import IngestClient, ViewerClient, http_get, stream_samples
from server.session import Session, SessionConfig
from tests.live_server import running
from tests.speech import speechlike
from wire import protocol as P

# A real server and clients over loopback sockets.
pytestmark = pytest.mark.system


def _reference(model, rig, pcm: np.ndarray, rate: int) -> list[P.Message]:
    """The session's delta messages as the per-frame path makes them: a sans-I/O Session, each
    frame's payload computed on its own."""
    s = Session(model, config=SessionConfig(sample_rate_hz=rate, sample_format="pcm_s16le"), rig=rig)
    frames = s.push_bytes(pcm.astype("<i2").tobytes()).frames + s.flush().frames
    out = []
    for f in frames:
        data, count, scale = f.payload(P.KIND_DELTAS, P.ENC_INT16)
        out.append(P.decode_message(P.pack_header(P.KIND_DELTAS, P.ENC_INT16, f.index, count, scale, 0, 0) + data))
    return out


def test_deltas_of_a_turn_are_computed_together_and_equal_the_per_frame_path(model, head):
    rate = 16000
    clips = [(speechlike(1.5, rate, seed=s) * 32767).astype(np.int16) for s in range(3)]

    async def main():
        async with running(model, head) as srv:
            ingests = [IngestClient(srv.url, session=f"t{i}", sample_rate_hz=rate) for i in range(3)]
            for ing in ingests:
                await ing.__aenter__()
            viewers = [ViewerClient(srv.url, session=f"t{i}", kind="deltas", encoding="int16") for i in range(3)]
            for v in viewers:
                await v.__aenter__()
            tasks = [asyncio.ensure_future(v.collect()) for v in viewers]
            # Not real time: blocks of all three sessions arrive together, several per loop turn.
            await asyncio.gather(
                *(stream_samples(ing, clip, realtime=False, block_s=0.02) for ing, clip in zip(ingests, clips))
            )
            ended = [await ing.end() for ing in ingests]
            got = await asyncio.gather(*tasks)
            for c in (*viewers, *ingests):
                await c.__aexit__(None, None, None)
            status, body = await http_get(srv.url, "/metrics")
            assert status == 200
            return ended, got, srv.turn_deltas.batches, srv.turn_deltas.frames, json.loads(body)

    ended, got, batches, frames, metrics = asyncio.run(main())
    for clip, end, rec in zip(clips, ended, got):
        want = _reference(model, head.rig, clip, rate)
        assert end["frames"] == len(want) == len(rec.frames) > 30
        assert [m.index for m in rec.frames] == list(range(len(want)))
        for m, w in zip(rec.frames, want):
            assert m.scale == w.scale
            np.testing.assert_array_equal(m.values, w.values)
        assert np.abs(np.array([m.values for m in rec.frames])).max() > 0  # the mouth moved
    # The streamed frames went through the turn's batch (those of the end's flush go out at once),
    # and some turns computed the deltas of more than one frame.
    total = sum(len(r.frames) for r in got)
    assert total // 2 < frames < total
    assert 0 < batches < frames
    # /metrics exports the same counters (docs/service.md, "Vertex deltas by loop turn")
    assert (metrics["delta_batches"], metrics["delta_batch_frames"]) == (batches, frames)
