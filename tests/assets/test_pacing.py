"""The one real-time pacing loop (assets.pacing): an absolute schedule on the loop clock."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from assets.pacing import paced_blocks
from realtime_core.errors import ConfigError


def test_blocks_cover_the_signal_and_leave_on_an_absolute_schedule():
    x = np.arange(1000)

    async def main():
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        got = []
        async for first, block in paced_blocks(x, 4000.0, block_s=0.025, start=t0):  # 100-sample blocks
            got.append((first, block.copy(), loop.time() - t0))
            if first == 300:
                await asyncio.sleep(0.06)  # a slow consumer: later blocks catch up, no drift
        return got

    got = asyncio.run(main())
    np.testing.assert_array_equal(np.concatenate([b for _, b, _ in got]), x)
    assert [f for f, _, _ in got] == list(range(0, 1000, 100))
    for first, block, at in got:
        due = (first + len(block)) / 4000.0
        assert at >= due - 1e-3  # never early
    assert got[-1][2] < 0.25 + 0.1  # the late block did not push the schedule back (0.25 s of audio)


def test_as_fast_as_possible_and_bad_rates():
    async def main():
        return [first async for first, _ in paced_blocks(np.zeros(50), 16000, block_s=0.001, realtime=False)]

    assert asyncio.run(main()) == list(range(0, 50, 16))

    async def bad():
        async for _ in paced_blocks(np.zeros(5), 0, block_s=0.02):
            pass

    with pytest.raises(ConfigError, match="rate_hz > 0"):
        asyncio.run(bad())
