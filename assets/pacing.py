"""Real-time pacing of audio blocks: the one loop that releases block i once its last sample "exists".

Server file sources (``server.sources.FileSource``), the ingest client (``clients.client.stream_samples``),
the latency and capacity benchmarks and the tests all stream recorded audio as if it came from a
microphone. They share this absolute schedule on the event loop's clock: block i (samples
``[first, first + n)``) is released at ``t0 + offset_s + (first + n) / rate_hz``, so delays do not
accumulate (no drift) and a late block is released at once. It lives in ``assets``, the lowest layer
allowed clocks and I/O (``realtime_core`` has neither), below both ``server`` and ``clients``.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import numpy as np

from realtime_core.errors import ConfigError


async def paced_blocks(
    samples: np.ndarray,
    rate_hz: float,
    *,
    block_s: float = 0.02,
    realtime: bool = True,
    offset_s: float = 0.0,
    start: float | None = None,
) -> AsyncIterator[tuple[int, np.ndarray]]:
    """Yield ``(first, block)``: consecutive blocks of ``samples`` (``(n, ...)``, split on axis 0) of
    ``round(block_s * rate_hz)`` samples, block i released on the absolute schedule of the module
    docstring from ``start`` (a loop time; default: now) plus ``offset_s``. ``realtime=False`` releases
    them as fast as the consumer takes them, yielding to the loop between blocks."""
    if not rate_hz > 0 or not block_s > 0:
        raise ConfigError(f"pacing needs rate_hz > 0 and block_s > 0, got {rate_hz} and {block_s}")
    loop = asyncio.get_running_loop()
    t0 = (loop.time() if start is None else start) + offset_s
    step = max(1, int(round(block_s * rate_hz)))
    for first in range(0, len(samples), step):
        block = samples[first : first + step]
        if realtime:
            delay = t0 + (first + len(block)) / rate_hz - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
        else:
            await asyncio.sleep(0)  # let the loop serve others between blocks
        yield first, block
