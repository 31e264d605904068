"""Vertex deltas encoded in a compute worker (server.workers): the payload the loop receives equals
the one it would have encoded itself with the same rig."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from server.session import Frame, SessionConfig
from server.timing import StageTimes
from server.workers import WorkerPool
from wire import protocol as P

# The built-in morph-target head (downloaded on first use); real worker processes.
pytestmark = [pytest.mark.system, pytest.mark.slow]


def test_worker_encodes_the_deltas_the_loop_would(model):
    from assets.heads.head import builtin_morph_head

    rig = builtin_morph_head().rig
    rng = np.random.default_rng(2)
    t = np.arange(16000) / 16000
    audio = (0.2 * np.sin(2 * np.pi * 3 * t) ** 2 * rng.standard_normal(t.size)).astype(np.float64)
    key = (P.KIND_DELTAS, P.ENC_INT16)

    async def main():
        pool = WorkerPool(model, 1, rig=rig)
        await pool.start()
        try:
            s = await pool.open(SessionConfig(sample_rate_hz=model.sample_rate_hz), rig=rig, times=StageTimes())
            s.precompute = (key,)
            frames = []
            for block in np.array_split(audio, 10):
                frames += (await s.push(block)).frames
            s.precompute = ()
            later = (await s.push(audio[:3200])).frames
            await s.close()
            return frames, later
        finally:
            await pool.stop()

    frames, later = asyncio.run(main())
    assert len(frames) > 20
    for f in frames:
        assert key in f._payloads  # came from the worker
        fresh = Frame(f.index, f.media_time, f.params, f.raw_params, 0.0, 0.0, rig)
        assert f._payloads[key] == fresh.payload(*key)
    assert later and all(key not in f._payloads for f in later)  # not asked for: the loop encodes
    assert any(np.frombuffer(f._payloads[key][0], "<i2").any() for f in frames)  # the mouth moved
