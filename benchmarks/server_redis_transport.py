"""Redis pub/sub vs Redis Streams as the cluster's frame transport (prints JSON; asserts nothing).

Starts its own ``redis-server`` on a free loopback port. For each transport, one publisher sends
``--sessions`` sessions' frames at 30 fps for ``--seconds`` (each message: a 32-byte header plus
``--payload`` bytes, the publish time inside) through redis-py's asyncio client, pipelined per
tick as the server's publisher does; one subscriber (another connection, the edge node's role)
receives them all: pub/sub with one subscription for all channels, Streams with one blocking
XREAD over all keys (``MAXLEN ~ 1000`` per key so memory stays bounded). Reported per transport:
publish-to-receipt latency (median, p99), messages lost, and the CPU seconds redis-server spent.
The two runs alternate (``--rounds``) so machine load hits both alike.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import shutil
import socket
import struct
import subprocess
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from server.timing import summarise

if TYPE_CHECKING:
    from redis.typing import KeyT, StreamIdT

STAMP = struct.Struct("<dI")  # publish time (s), sequence number


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def _run(url: str, transport: str, sessions: int, seconds: float, payload: int) -> dict:
    import redis.asyncio as aioredis

    pub = aioredis.Redis.from_url(url)
    sub = aioredis.Redis.from_url(url)
    names = [f"bench:{transport}:{i}" for i in range(sessions)]
    lat: list[float] = []
    got = 0
    n_ticks = int(seconds * 30)
    expected = n_ticks * sessions
    body = b"\x00" * max(0, payload + 32 - STAMP.size)
    done = asyncio.Event()
    stop = False  # consumers end on their own: cancelling a blocked redis-py read can hang it

    def on_data(data: bytes) -> None:
        nonlocal got
        t, _ = STAMP.unpack_from(data)
        lat.append(time.time() - t)
        got += 1
        if got >= expected:
            done.set()

    if transport == "pubsub":
        ps = sub.pubsub(ignore_subscribe_messages=True)
        await ps.subscribe(*names)

        async def consume() -> None:
            while not stop:
                msg = await ps.get_message(timeout=0.2)
                if msg is not None:
                    on_data(msg["data"])
    else:
        await pub.delete(*names)

        async def consume() -> None:
            # the keys were just deleted: everything from now on
            last: dict[KeyT, StreamIdT] = {n: "0" for n in names}
            while not stop:
                # RESP2 (redis-py's default protocol) replies [[stream, [(id, {field: value})]]]; redis-py
                # types the reply as the union of its RESP2 and RESP3 shapes
                out = cast("list[list[Any]]", await sub.xread(last, block=200, count=1000))
                for key, entries in out:
                    k = key.decode()
                    for eid, fields in entries:
                        last[k] = eid
                        on_data(fields[b"m"])

    consumer = asyncio.ensure_future(consume())
    await asyncio.sleep(0.3)
    loop = asyncio.get_running_loop()
    t0 = loop.time()
    seq = 0
    for tick in range(n_ticks):
        delay = t0 + tick / 30 - loop.time()
        if delay > 0:
            await asyncio.sleep(delay)
        pipe = pub.pipeline(transaction=False)
        for n in names:
            msg = STAMP.pack(time.time(), seq) + body
            seq += 1
            if transport == "pubsub":
                pipe.publish(n, msg)
            else:
                pipe.xadd(n, {"m": msg}, maxlen=1000, approximate=True)
        await pipe.execute()
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(done.wait(), 5)
    stop = True
    await asyncio.wait_for(consumer, 5)
    if transport == "pubsub":
        await asyncio.wait_for(ps.aclose(), 5)
    else:
        await asyncio.wait_for(pub.delete(*names), 5)
    await asyncio.wait_for(pub.aclose(), 5)
    await asyncio.wait_for(sub.aclose(), 5)
    return {"latency_ms": summarise(np.array(lat)), "lost": expected - got, "messages": expected}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="server_redis_transport", description=__doc__.split("\n\n")[0])
    ap.add_argument("--sessions", type=int, default=50, help="sessions (channels / stream keys)")
    ap.add_argument("--seconds", type=float, default=5.0, help="length of each run")
    ap.add_argument("--payload", type=int, default=16, help="payload bytes per message (params: 16)")
    ap.add_argument("--rounds", type=int, default=2, help="alternating runs per transport")
    args = ap.parse_args(argv)
    binary = shutil.which("redis-server")
    if binary is None:
        raise SystemExit("server_redis_transport: redis-server is not installed (scripts/setup.sh installs it)")
    port = _free_port()
    proc = subprocess.Popen(
        [binary, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    url = f"redis://127.0.0.1:{port}/0"
    results: dict[str, list] = {"pubsub": [], "streams": []}
    try:
        time.sleep(0.5)
        for _ in range(args.rounds):
            for transport in ("pubsub", "streams"):
                cpu0 = _cpu_s(proc.pid)
                r = asyncio.run(
                    asyncio.wait_for(_run(url, transport, args.sessions, args.seconds, args.payload), args.seconds + 30)
                )
                r["redis_cpu_s"] = round(_cpu_s(proc.pid) - cpu0, 3)
                results[transport].append(r)
    finally:
        proc.terminate()
        proc.wait(10)
    print(
        json.dumps(
            {
                "benchmark": "server_redis_transport",
                "sessions": args.sessions,
                "fps": 30,
                "seconds": args.seconds,
                "payload_bytes": args.payload,
                "runs": results,
                "loadavg": [round(x, 2) for x in os.getloadavg()],
            },
            indent=2,
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
