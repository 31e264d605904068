"""What one viewer's message costs the server's fan-out (prints JSON; asserts nothing).

``server.live.deliver`` to N real websockets connections over loopback (a child process drains them,
as a viewer would), CPU time of the sending thread (``time.thread_time_ns``: user and kernel, so the
``send`` system call and the loopback delivery it runs are included) per viewer and message, for a
parameter frame (48 bytes) and a vertex frame of the built-in head (16.7 KB int16). The capacity
benchmark's cost model charges a parameter viewer ~0.0012 cores (~40 us per frame at 30 frames/s);
this is the part that is the viewer's own write.

``python -m benchmarks.server_fanout [--viewers 1,10,40] [--rounds 40]``
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import time
import types

import numpy as np

PER_ROUND = 50  # messages to every viewer per timed round (a round then sleeps 20 ms: the socket drains)


def _drain(port: int, n: int) -> None:
    """Child process: n viewer connections reading and discarding every message."""
    from websockets.asyncio.client import connect

    async def main() -> None:
        async def one() -> None:
            async with connect(f"ws://127.0.0.1:{port}/", compression=None, max_size=None) as ws:
                async for _ in ws:
                    pass

        await asyncio.gather(*(one() for _ in range(n)), return_exceptions=True)

    asyncio.run(main())


async def measure(n: int, rounds: int, size: int, queued: list[int] | None = None) -> float:
    """CPU microseconds per viewer and message of ``deliver`` to n connected viewers; ``queued[0]`` (if given)
    is increased by the messages that took the slow path (a socket buffer full: queued, not written)."""
    queued = [0] if queued is None else queued
    from websockets.asyncio.server import ServerConnection, serve

    from server.live import Viewer, deliver

    conns: list[ServerConnection] = []
    all_in = asyncio.Event()

    async def handler(ws: ServerConnection) -> None:
        conns.append(ws)
        if len(conns) == n:
            all_in.set()
        await ws.wait_closed()

    async with serve(handler, "127.0.0.1", 0, compression=None) as srv:
        port = srv.sockets[0].getsockname()[1]
        child = mp.get_context("spawn").Process(target=_drain, args=(port, n))
        child.start()
        await all_in.wait()
        # Viewer needs its server and session only for the slow path's bookkeeping (a viewer whose socket
        # buffer is full is queued instead of written to: counted, its queue emptied after the round).
        server = types.SimpleNamespace(
            config=types.SimpleNamespace(viewer_queue=PER_ROUND, viewer_max_behind_s=3600.0), dropped=0, closed_slow=0
        )
        live = types.SimpleNamespace(dropped=0)
        viewers = [Viewer(ws, live, kind=1, encoding=1, audio=False, server=server) for ws in conns]  # type: ignore[arg-type]
        msg = b"x" * size
        cpu = []
        for _ in range(rounds):
            t0 = time.thread_time_ns()
            for _ in range(PER_ROUND):
                deliver(viewers, msg, 0.0)
            cpu.append((time.thread_time_ns() - t0) / (PER_ROUND * n) / 1e3)
            for v in viewers:
                queued[0] += len(v.queue)
                v.queue.clear()
            # the next round starts with empty socket buffers (every write the fast path's), within 1 s
            for _ in range(50):
                await asyncio.sleep(0.02)
                if all(ws.transport.get_write_buffer_size() == 0 for ws in conns):
                    break
        for ws in conns:
            await ws.close()
        child.join()
    return float(np.median(cpu))


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--viewers", default="1,10,40", help="viewer counts (comma-separated)")
    ap.add_argument("--rounds", type=int, default=40)
    args = ap.parse_args(argv)
    report: dict = {"cpu_us_per_viewer_message": {}}
    for n in (int(x) for x in args.viewers.split(",")):
        report["cpu_us_per_viewer_message"][f"{n} viewers"] = {
            "params_48_B": round(asyncio.run(measure(n, args.rounds, 48)), 2),
            "deltas_16.7_KB": round(asyncio.run(measure(n, args.rounds, 32 + 2 * 8319)), 2),
        }
    print(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    main()
