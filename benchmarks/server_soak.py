"""Soak test of the streaming server: RSS growth, frames lost, loop lag and viewer latency over
minutes, optionally under hostile traffic (prints JSON; asserts nothing).

Setup: ``facecast serve`` in its own process (the benchmark model, the built-in head). This process
runs ``--sessions`` real-time ingests (16 kHz speech-like audio in 20 ms blocks, looped) with
``--viewers`` parameter viewers each, and records every frame's end-to-end latency: from the send
of the block holding the last sample the frame needs to the viewer's receipt (the server's whole
overhead beyond the algorithmic delay). Every 5 s it samples the server's resident memory
(``VmRSS``). With ``--hostile`` the second half of the run adds, from a separate process, a
100x-real-time ingest (paced by the server's ingest guard) and a stream of malformed or hostile
messages (bad starts, deep JSON, garbage audio, invalid controls, bad viewer queries, wrong
Origins); the report gives the healthy viewers' p99 in the quiet and the hostile half.

Reported: RSS at warm-up (after 10% of the run) and at the end, growth in percent; frames lost
(index gaps or missing frames per viewer); loop lag p99 from the server's ``/metrics``; end-to-end
p50/p99 per phase; hostile messages sent; server still healthy at the end.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import sys
import time
from pathlib import Path

import numpy as np

from assets.pacing import paced_blocks
from benchmarks.server_harness import FrameLog, ServerProcess, benchmark_model, record_viewer, speech_signal
from server.timing import summarise

RATE = 16000
BLOCK = 320  # 20 ms


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


async def _hostile(url: str, seconds: float, counter) -> None:
    """Hostile traffic for ``seconds``: a fast ingest plus a stream of malformed messages."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import InvalidStatus, WebSocketException
    from websockets.typing import Origin

    from clients.client import ws_url

    pcm = speech_signal(20.0, seed=5).tobytes()
    t_end = time.monotonic() + seconds

    async def flood_ingest() -> None:
        n = 0
        while time.monotonic() < t_end:
            n += 1
            try:
                async with connect(ws_url(url, "/ingest"), compression=None) as ws:
                    await ws.send(json.dumps({"type": "start", "session": f"flood{n}", "sample_rate": RATE}))
                    await ws.recv()
                    while time.monotonic() < t_end:  # 100x real time: 2 s of audio every 20 ms
                        await ws.send(pcm[: 2 * RATE * 2])
                        await asyncio.sleep(0.02)
            except (OSError, WebSocketException):
                await asyncio.sleep(0.1)

    bad_first: list[str | bytes] = [
        b"\x00\xff" * 10,
        "{garbage",
        "[" * 5000 + "]" * 5000,
        json.dumps({"type": "start"}),
        json.dumps({"type": "start", "session": "x" * 100, "sample_rate": RATE}),
        json.dumps({"type": "start", "session": "h", "sample_rate": 10**9}),
    ]

    async def spam() -> None:
        i = 0
        while time.monotonic() < t_end:
            i += 1
            try:
                if i % 10 == 0:  # a started session sent junk: invalid controls (answered), then garbage audio
                    async with connect(ws_url(url, "/ingest"), compression=None) as ws:
                        await ws.send(json.dumps({"type": "start", "session": f"junk{i}", "sample_rate": RATE}))
                        await ws.recv()
                        for _ in range(50):
                            await ws.send(json.dumps({"type": "control", "gain": {"jaw": 99}}))
                            counter.value += 1
                        await ws.send(b"\x01\x02\x03")
                        counter.value += 1
                        await asyncio.wait_for(ws.wait_closed(), 5)
                elif i % 10 == 5:
                    async with connect(
                        ws_url(url, "/view?session=none&kind=smell"),
                        compression=None,
                        origin=Origin("http://evil.example"),
                    ):
                        pass
                else:
                    async with connect(ws_url(url, "/ingest"), compression=None) as ws:
                        await ws.send(bad_first[i % len(bad_first)])
                        counter.value += 1
                        await asyncio.wait_for(ws.wait_closed(), 5)
            except InvalidStatus:
                counter.value += 1
            except (OSError, WebSocketException, TimeoutError):
                pass

    await asyncio.gather(flood_ingest(), spam())


def _hostile_proc(url: str, seconds: float, counter) -> None:
    asyncio.run(_hostile(url, seconds, counter))


async def _run(server: ServerProcess, model, *, seconds: float, sessions: int, viewers: int, hostile: bool) -> dict:
    from clients.client import IngestClient, ServerClosed, http_get

    url = server.url
    mf = model.frontend.mfcc
    d = model.frontend.tc
    speech = speech_signal(20.0)
    logs = [[FrameLog() for _ in range(viewers)] for _ in range(sessions)]
    block_sent: list[list[float]] = [[] for _ in range(sessions)]
    rss: list[tuple[float, float]] = []
    phase_metrics: dict[str, dict] = {}
    hostile_count = mp.get_context("spawn").Value("l", 0)
    hostile_proc = None
    dropped: list[dict] = []
    t_start = time.monotonic()
    half = t_start + seconds / 2

    async def one_session(s: int) -> dict:
        n_blocks = int(seconds * RATE / BLOCK)
        tasks: list[asyncio.Future] = []
        try:
            async with IngestClient(url, session=f"soak{s}", sample_rate_hz=RATE) as ing:
                tasks = [asyncio.ensure_future(record_viewer(url, f"soak{s}", log=log)) for log in logs[s]]
                await asyncio.sleep(0.5)
                loop = asyncio.get_running_loop()
                t0 = loop.time() + s * 0.02 / max(1, sessions)  # staggered across a block
                looped = np.concatenate(
                    [speech[(b * BLOCK) % (len(speech) - BLOCK) :][:BLOCK] for b in range(n_blocks)]
                )
                async for _, block in paced_blocks(looped, RATE, block_s=BLOCK / RATE, start=t0):
                    await ing.send(block)
                    block_sent[s].append(time.time())
                ended = await ing.end()
                await asyncio.gather(*tasks)
                return ended
        except ServerClosed as exc:
            # One ingest lost (reported, its missing frames counted as lost): the soak goes on.
            dropped.append(
                {"session": s, "after_s": round(time.monotonic() - t_start, 1), "code": exc.code, "reason": exc.reason}
            )
            await asyncio.gather(*tasks, return_exceptions=True)
            return {"frames": mf.n_frames_for(n_blocks * BLOCK)}

    async def sample_rss() -> None:
        while True:
            rss.append((time.monotonic() - t_start, _rss_mb(server.proc.pid)))
            await asyncio.sleep(5.0)

    async def phases() -> None:
        nonlocal hostile_proc
        await asyncio.sleep(max(0.0, half - time.monotonic()))
        phase_metrics["quiet"] = json.loads((await http_get(url, "/metrics"))[1])
        if hostile:
            hostile_proc = mp.get_context("spawn").Process(
                target=_hostile_proc, args=(url, seconds / 2 - 1, hostile_count), daemon=True
            )
            hostile_proc.start()

    sampler = asyncio.ensure_future(sample_rss())
    phase_task = asyncio.ensure_future(phases())
    ended = await asyncio.gather(*(one_session(s) for s in range(sessions)))
    sampler.cancel()
    await phase_task
    if hostile_proc is not None:
        hostile_proc.join(30)
        if hostile_proc.is_alive():  # the sessions ended early (e.g. lost): do not outlive them
            hostile_proc.terminate()
    status, _body = await http_get(url, "/health")
    final = json.loads((await http_get(url, "/metrics"))[1])
    rss.append((time.monotonic() - t_start, _rss_mb(server.proc.pid)))

    # End-to-end latency per frame, split at the half-way time (wall clock of the block send).
    half_wall = time.time() - (time.monotonic() - half)
    e2e: dict[str, list[float]] = {"quiet": [], "hostile" if hostile else "second_half": []}
    lost = 0
    for s in range(sessions):
        sent = np.array(block_sent[s])
        for log in logs[s]:
            idx = np.array(log.index)
            lost += (
                int(ended[s]["frames"] - len(idx)) + int(np.sum(np.diff(idx) != 1)) if len(idx) else ended[s]["frames"]
            )
            need = np.array([mf.frame_start(int(k) + d) + mf.window_len for k in idx])
            live = (need - 1) // BLOCK < len(sent)
            t_need = sent[(need[live] - 1) // BLOCK]
            lat = np.array(log.received)[live] - t_need
            e2e["quiet"].append(lat[t_need < half_wall])
            e2e[list(e2e)[1]].append(lat[t_need >= half_wall])
    warm = next((m for t, m in rss if t >= seconds * 0.1), rss[0][1])
    return {
        "rss_mb": {
            "warm": round(warm, 1),
            "end": round(rss[-1][1], 1),
            "growth_percent": round(100 * (rss[-1][1] - warm) / warm, 2),
            "samples": [(round(t, 1), round(m, 1)) for t, m in rss],
        },
        "frames_lost": lost,
        "frames_expected": int(sum(e["frames"] for e in ended) * viewers),
        "end_to_end_ms": {k: summarise(np.concatenate(v)) for k, v in e2e.items()},
        "loop_lag_p99_ms": {
            "quiet": phase_metrics["quiet"]["timings_ms"].get("loop_lag", {}).get("p99_ms"),
            "end": final["timings_ms"].get("loop_lag", {}).get("p99_ms"),
        },
        "ingests_lost": dropped,
        "hostile_messages": int(hostile_count.value),
        "closes_by_code": final["closes"],
        "healthy_at_end": status == 200,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="facecast bench soak", description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=30.0, help="length of the run")
    ap.add_argument("--sessions", type=int, default=4, help="real-time sessions")
    ap.add_argument("--viewers", type=int, default=5, help="parameter viewers per session")
    ap.add_argument("--hostile", action="store_true", help="hostile traffic during the second half")
    ap.add_argument("--model", type=Path, default=None, help="model file (default: shipped, else paper-size random)")
    args = ap.parse_args(argv)
    model, model_path, model_desc = benchmark_model(args.model)
    server = ServerProcess(model_path, head=True)
    load_before = os.getloadavg()
    try:
        result = asyncio.run(
            _run(
                server,
                model,
                seconds=args.minutes * 60,
                sessions=args.sessions,
                viewers=args.viewers,
                hostile=args.hostile,
            )
        )
    except Exception:
        rc = server.stop()
        sys.stderr.write(f"server exit code {rc}; its last output:\n" + "".join(server.log_tail))
        raise
    rc = server.stop()
    result.update(
        {
            "benchmark": "server_soak",
            "model": model_desc,
            "minutes": args.minutes,
            "sessions": args.sessions,
            "viewers_per_session": args.viewers,
            "server_exit_code": rc,
            "loadavg_before": [round(x, 2) for x in load_before],
            "loadavg_after": [round(x, 2) for x in os.getloadavg()],
        }
    )
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
