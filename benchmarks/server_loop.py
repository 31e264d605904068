"""The event loop's share of the server's per-message CPU, asyncio's loop against uvloop (prints JSON; asserts nothing).

Two microbenchmarks of the server's own I/O paths, each run on both loops in alternation (``--pairs`` times,
each pair in the order A B then B A), CPU time of the server's thread (``time.thread_time_ns``: user and
kernel, so the system calls are included), medians over the pairs:

* **receive**: N ingest-like connections in a child process each send a 1,280-byte binary message (20 ms of
  16 kHz int16) every 20 ms for ``--seconds``; the server is websockets with the server's own connection class
  (``server.app.FacecastConnection``), either with a sink that takes every message in the data callback (the
  ingest fast path, ``fast``) or with a handler task that ``recv``s each (websockets' usual path, ``queue``).
  The sink does nothing: this is the cost of getting a block to the session, not of the session's work.
  CPU us per received message.
* **fan-out**: ``server.live.deliver`` of a parameter (48 B) and a vertex (16.7 KB) message to N viewers
  over loopback (``benchmarks.server_fanout``). CPU us per viewer and message.

``python -m benchmarks.server_loop [--connections 10,40] [--viewers 10,40] [--pairs 3] [--seconds 4]``
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import time

import numpy as np

from benchmarks.server_fanout import measure as measure_fanout
from server.eventloop import EVENT_LOOPS
from server.eventloop import run as run_on_loop

BLOCK_BYTES = 1280  # 20 ms of 16 kHz int16
PERIOD_S = 0.02


def _senders(port: int, n: int, seconds: float) -> None:
    """Child process: n connections, each sending one block every 20 ms (staggered) for ``seconds``."""
    from websockets.asyncio.client import connect

    async def main() -> None:
        block = bytes(BLOCK_BYTES)
        loop = asyncio.get_running_loop()
        t0 = loop.time() + 0.5

        async def one(j: int) -> None:
            async with connect(f"ws://127.0.0.1:{port}/", compression=None, max_size=None) as ws:
                k = 0
                while k * PERIOD_S < seconds:
                    await asyncio.sleep(max(0.0, t0 + j * PERIOD_S / n + k * PERIOD_S - loop.time()))
                    await ws.send(block)
                    k += 1

        await asyncio.gather(*(one(j) for j in range(n)))

    asyncio.run(main())


async def _measure_receive(n: int, seconds: float, path: str) -> float:
    """CPU microseconds of the server's thread per received message (``path``: "fast" or "queue")."""
    from websockets.asyncio.server import ServerConnection, serve

    from server.app import FacecastConnection

    received = 0
    first = asyncio.Event()
    cpu0 = 0

    def count() -> None:
        nonlocal received, cpu0
        if received == 0:  # from the first message: the handshakes are not the receive path
            cpu0 = time.thread_time_ns()
            first.set()
        received += 1

    def sink(data: bytes) -> bool:
        count()
        return True

    async def handler(ws: ServerConnection) -> None:
        if path == "fast":
            assert isinstance(ws, FacecastConnection)
            ws.sink = sink
            await ws.wait_closed()
        else:
            async for _ in ws:
                count()

    async with serve(handler, "127.0.0.1", 0, compression=None, create_connection=FacecastConnection) as srv:
        port = srv.sockets[0].getsockname()[1]
        child = mp.get_context("spawn").Process(target=_senders, args=(port, n, seconds))
        child.start()
        await first.wait()
        while child.is_alive():
            await asyncio.sleep(0.05)
        cpu1 = time.thread_time_ns()
        child.join()
    return (cpu1 - cpu0) / max(received, 1) / 1e3


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--connections", default="10,40", help="ingest connections (comma-separated)")
    ap.add_argument("--viewers", default="10,40", help="viewer counts (comma-separated)")
    ap.add_argument("--pairs", type=int, default=3, help="A/B pairs per figure (order alternating)")
    ap.add_argument("--seconds", type=float, default=4.0, help="streaming time of one receive measurement")
    ap.add_argument("--rounds", type=int, default=40, help="fan-out rounds of one measurement")
    args = ap.parse_args(argv)

    def ab(measure) -> dict:
        got: dict[str, list[float]] = {name: [] for name in EVENT_LOOPS}
        for pair in range(args.pairs):
            for name in EVENT_LOOPS if pair % 2 == 0 else EVENT_LOOPS[::-1]:
                got[name].append(run_on_loop(measure(), name))
        med = {name: round(float(np.median(v)), 2) for name, v in got.items()}
        return {
            "median": med,
            "runs": {name: [round(x, 2) for x in v] for name, v in got.items()},
            "uvloop_over_asyncio": round(med["uvloop"] / med["asyncio"], 3),
        }

    report: dict = {"receive_cpu_us_per_message": {}, "fanout_cpu_us_per_viewer_message": {}}
    for n in (int(x) for x in args.connections.split(",") if x):
        for path in ("fast", "queue"):
            r = ab(lambda n=n, path=path: _measure_receive(n, args.seconds, path))
            report["receive_cpu_us_per_message"][f"{n} connections, {path}"] = r
            print(json.dumps({"receive": n, "path": path, **r}), flush=True)
    for n in (int(x) for x in args.viewers.split(",") if x):
        for label, size in (("params_48_B", 48), ("deltas_16.7_KB", 32 + 2 * 8319)):
            queued = [0]
            r = ab(lambda n=n, size=size, queued=queued: measure_fanout(n, args.rounds, size, queued))
            r["queued_not_written"] = queued[0]  # slow-path messages (a full socket buffer), both loops together
            report["fanout_cpu_us_per_viewer_message"][f"{n} viewers, {label}"] = r
            print(json.dumps({"fanout": n, "message": label, **r}), flush=True)
    report["machine"] = {"cpus": os.cpu_count(), "loadavg_1_5_15_after": [round(x, 2) for x in os.getloadavg()]}
    print(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    main()
