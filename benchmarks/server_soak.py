"""Soak test of the streaming server: RSS growth, frames lost, loop lag and viewer latency over
minutes, optionally under hostile traffic (prints JSON; asserts nothing).

Setup: ``facecast serve`` in its own process (the benchmark model, the built-in head, the default
configuration). The clients run in processes of their own, those of the capacity benchmark
(``benchmarks.server_capacity.ClientProcesses``): one streams ``--sessions`` real-time ingests
(16 kHz speech-like audio in 20 ms blocks, looped), one holds ``--viewers`` parameter viewers per
session, so a client starved on a loaded machine is not measured as server latency. Every frame's
end-to-end latency is recorded: from the send of the block holding the last sample the frame needs
to the viewer's receipt (the server's whole overhead beyond the algorithmic delay). Every 5 s the
server's resident memory (``VmRSS``) is sampled.

With ``--hostile`` the second half adds, from a third process (connections from another loopback
address, ``--hostile-from``: the attacker is a client of its own), a 100x-real-time ingest (paced by
the server's ingest guard) and malformed or hostile messages of every kind (``hostile_traffic``):
started ingests pipelining invalid controls (each answered ``rejected``) then a closing message
(garbage or NaN audio, non-JSON text, deep JSON, unknown types, a second start, oversized binary or
text), bad first messages, viewers of the healthy session pipelining invalid expression controls
then junk, bad viewer queries, and raw requests with bad headers (Host, Origin, WebSocket key and
version, huge or too many header lines, a path too long, not HTTP). A message counts once the
server answered it (a reply, a close code or an HTTP status). The hostile half lasts at least half
the run and until ``--hostile-messages`` were answered, paced by default to spread them over it.

Reported: RSS at warm-up (after 10% of the run), at the end of the quiet half, peak and end; frames
lost per viewer; loop lag p99 from the server's ``/metrics``; end-to-end p50/p99 per phase and per
viewer, and the hostile/quiet p99 ratio; the hostile messages sent and answered per scenario, the
close codes and HTTP statuses the sender received and the server's closes by code in the second
half; /health during the hostile half; server alive and healthy at the end.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import os
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.server_capacity import ClientProcesses
from benchmarks.server_harness import ServerProcess, benchmark_model, speech_signal
from server.timing import summarise

RATE = 16000
BLOCK = 320  # 20 ms (the capacity benchmark's client processes: benchmarks.server_capacity.BLOCK_S)


def _rss_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


# -- the hostile sender ------------------------------------------------------------------------------
#
# Most malformed messages close their connection (docs/protocol.md section 5), so one per connection;
# the ones the protocol answers without closing (invalid controls on a started ingest, invalid
# expression controls from a viewer) ride many to a connection, which ends with one closing message.
# Every message counts once it is *answered*: a reply, a close code or an HTTP status.

DEEP = "[" * 5000 + "]" * 5000
BAD_CONTROLS = [  # answered {"type": "rejected"}; the session goes on
    {"type": "control", "gain": {"jaw": 99}},
    {"type": "control", "gain": {"mouth_open": -5}},
    {"type": "control", "smoothing_ms": "soon"},
    {"type": "control", "smoothing_ms": 10**9},
    {"type": "control", "eyebrows": 1},
    {"type": "control", "expression": {"name": "smirk", "intensity": 1}},
    {"type": "control", "expression": {"name": "smile", "intensity": 7}},
    {"type": "control", "expression_ease_s": -1},
]
BAD_VIEWER_CONTROLS = [  # answered {"type": "rejected"}: the viewer stays
    {"type": "control", "expression": {"name": "smirk"}},
    {"type": "control", "expression": {"name": "smile", "intensity": -3}},
    {"type": "control", "expression": {"name": "smile", "at": 1e9}},
    {"type": "control", "expression_ease_s": 99},
]
INGEST_CLOSERS: list[str | bytes] = [  # after a start: each closes the connection with its code
    b"\x01\x02\x03",  # not whole samples (1007)
    "not json",  # text that is not JSON where audio is expected (1003)
    DEEP,  # nesting beyond 8 levels (1007)
    json.dumps({"type": "rewind"}),  # unknown type (1008)
    json.dumps({"type": "start", "session": "again", "sample_rate": RATE}),  # a second start (1008)
    b"\x00" * (2 << 20),  # over max_message_bytes (1009)
    json.dumps({"type": "control", "pad": "x" * (100 << 10)}),  # text over 64 KiB (1009)
]
FIRST_MESSAGES: list[str | bytes] = [  # the first message of a fresh ingest: each closes it
    b"\x00\xff" * 10,  # binary before start (1003)
    "{garbage",  # not JSON (1007)
    DEEP,
    "[1, 2]",  # not an object (1007)
    json.dumps({"type": "start"}),  # fields missing (4400)
    json.dumps({"type": "start", "session": "x" * 100, "sample_rate": RATE}),  # bad name (4400)
    json.dumps({"type": "start", "session": "h", "sample_rate": 10**9}),  # bad rate (4400)
    json.dumps({"type": "start", "session": "h", "sample_rate": RATE, "format": "mp3"}),
    json.dumps({"type": "start", "session": "h", "sample_rate": RATE, "channels": 99}),
    json.dumps({"type": "start", "session": "h", "sample_rate": RATE, "admin": True}),  # unknown field (4400)
    json.dumps({"type": "control", "gain": {"jaw": 1}}),  # a control before start (1008)
    b"\x00" * (2 << 20),  # oversized (1009)
]
VIEWER_CLOSERS: list[str | bytes] = [b"\x00\x01", "hello", DEEP, json.dumps({"type": "end"})]  # 1008 each
BAD_QUERIES = [  # a bad viewer query: closed after the upgrade (4004 / 4400)
    "session=none",
    "session=" + "%2F" * 30,
    "session={s}&kind=smell",
    "session={s}&encoding=mp3",
    "session={s}&kind=deltas&encoding=float64",
    "session={s}&audio=maybe",
    "&".join(f"f{i}=1" for i in range(40)) + "&session={s}",
]
RAW_REQUESTS = [  # bad headers and requests, refused before any handshake (an HTTP status)
    "GET /ingest HTTP/1.1\r\nHost: evil.example\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",  # DNS rebinding (403)
    "GET /view?session={s} HTTP/1.1\r\nHost: 127.0.0.1\r\nOrigin: http://evil.example\r\nUpgrade: websocket\r\n"
    "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",  # 403
    "GET /ingest HTTP/1.1\r\nHost: 127.0.0.1\r\nOrigin: null\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",  # null Origin (403)
    "GET /admin HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",  # no such endpoint (404)
    "GET /ingest HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\r\n",  # no key (400)
    "GET /ingest HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: short\r\nSec-WebSocket-Version: 99\r\n\r\n",  # bad key and version (400/426)
    "GET /" + "a" * 3000 + " HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",  # long path (414)
    "GET /ingest HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Pad: " + "y" * 20000 + "\r\n\r\n",  # huge header line
    "\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03 binary junk\r\n\r\n",  # not HTTP (a TLS hello)
    "GET /health HTTP/1.1\r\n" + "".join(f"X-H{i}: {i}\r\n" for i in range(300)) + "\r\n",  # too many headers
]


SCENARIO_CYCLE = (  # a worker's turn, in these proportions
    "ingest_controls",
    "ingest_controls",
    "ingest_first",
    "ingest_first",
    "viewer_controls",
    "viewer_query",
    "bad_request",
    "bad_request",
)
SCENARIOS = frozenset(SCENARIO_CYCLE) | {"flood"}


@dataclass
class HostileTally:
    """What the hostile sender did: messages sent and answered, per scenario; close codes and HTTP
    statuses it received; connections that ended without either (timeouts, resets); flood audio."""

    sent: Counter = field(default_factory=Counter)
    answered: Counter = field(default_factory=Counter)
    close_codes: Counter = field(default_factory=Counter)
    http_status: Counter = field(default_factory=Counter)
    unanswered: Counter = field(default_factory=Counter)
    connections: int = 0
    flood_audio_s: float = 0.0

    def report(self) -> dict:
        return {
            "sent": sum(self.sent.values()),
            "answered": sum(self.answered.values()),
            "sent_by_scenario": dict(self.sent),
            "answered_by_scenario": dict(self.answered),
            "close_codes": {str(k): v for k, v in sorted(self.close_codes.items(), key=lambda kv: str(kv[0]))},
            "http_status": {str(k): v for k, v in sorted(self.http_status.items(), key=lambda kv: str(kv[0]))},
            "connections_unanswered": dict(self.unanswered),
            "connections": self.connections,
            "flood_audio_s": round(self.flood_audio_s, 1),
        }


async def hostile_traffic(
    url: str,
    sessions: list[str],
    *,
    stop,
    tally: HostileTally,
    on_answer=None,
    workers: int = 6,
    local_host: str | None = None,
    scenarios: frozenset[str] = SCENARIOS,
    rate_per_s: float | None = None,
) -> None:
    """Hostile traffic until ``stop()`` is true: ``workers`` concurrent connections cycling through
    the scenarios (started ingests sending invalid controls then a closing message, bad first
    messages, viewers of ``sessions`` (the healthy ones) sending invalid controls then junk, bad
    viewer queries, raw requests with bad headers; ``scenarios`` picks some) and, with ``"flood"``,
    one ingest sending 2 s of audio every 20 ms (100x real time; the server's ingest guard paces
    it). ``local_host``: the source address of the connections (a loopback alias: the attacker is a client of its own);
    ``rate_per_s``: answered messages a second on average (None: as fast as the workers go)."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus

    from clients.client import ws_url

    host, port = url.split("//", 1)[1].rsplit(":", 1)
    local: dict[str, Any] = {"local_addr": (local_host, 0)} if local_host else {}
    answer = on_answer or (lambda n: None)

    def answered(scenario: str, n: int = 1) -> None:
        tally.answered[scenario] += n
        answer(n)

    async def text_reply(ws) -> None:
        """The next text message (a reply), skipping the frames a viewer receives meanwhile."""
        while not isinstance(await ws.recv(), str):
            pass

    async def until_closed(ws) -> None:
        while True:
            await ws.recv()

    async def conversation(scenario: str, path: str, first: list, repeat: list, closer) -> None:
        """Send ``first`` (a start: not counted), then ``repeat`` (each answered with a reply,
        pipelined), then ``closer`` (answered by the close code). With no closer the request itself
        (a bad viewer query) is the hostile message; a refused handshake is one too (an HTTP status)."""
        tally.connections += 1
        try:
            async with connect(ws_url(url, path), compression=None, max_size=None, open_timeout=10, **local) as ws:
                if closer is None:
                    tally.sent[scenario] += 1
                for m in first:
                    await ws.send(m)
                    await asyncio.wait_for(text_reply(ws), 10)  # started / description
                for m in repeat:
                    await ws.send(m)
                    tally.sent[scenario] += 1
                for _ in repeat:
                    await asyncio.wait_for(text_reply(ws), 10)
                    answered(scenario)
                if closer is not None:
                    await ws.send(closer)
                    tally.sent[scenario] += 1
                await asyncio.wait_for(until_closed(ws), 10)  # ends in ConnectionClosed
        except ConnectionClosed as exc:
            code = exc.rcvd.code if exc.rcvd else None
            tally.close_codes[code] += 1
            if code is not None:
                answered(scenario)
            else:
                tally.unanswered[scenario + ": no close frame"] += 1
        except InvalidStatus as exc:
            tally.sent[scenario] += 1
            tally.http_status[exc.response.status_code] += 1
            answered(scenario)
        except (OSError, InvalidHandshake, TimeoutError) as exc:
            tally.unanswered[f"{scenario}: {type(exc).__name__}"] += 1

    async def raw(scenario: str, request: str) -> None:
        tally.connections += 1
        tally.sent[scenario] += 1
        try:
            reader, writer = await asyncio.wait_for(asyncio.open_connection(host, int(port), **local), 10)
            try:
                writer.write(request.encode("latin-1"))
                await writer.drain()
                line = await asyncio.wait_for(reader.readline(), 10)
            finally:
                writer.close()
            parts = line.split()
            if len(parts) >= 2 and parts[1].isdigit():
                tally.http_status[int(parts[1])] += 1
                answered(scenario)
            else:  # the server hung up without a status (e.g. on a request that is not HTTP)
                tally.http_status["closed without a status"] += 1
                answered(scenario)
        except (OSError, TimeoutError) as exc:
            tally.unanswered[f"{scenario}: {type(exc).__name__}"] += 1

    loop = asyncio.get_running_loop()
    t0 = loop.time()

    async def worker(w: int) -> None:
        i = w
        while not stop():
            if rate_per_s is not None:  # at most rate_per_s answered messages a second on average
                while sum(tally.answered.values()) >= rate_per_s * (loop.time() - t0) and not stop():
                    await asyncio.sleep(0.01)
            i += workers
            s = sessions[i % len(sessions)] if sessions else "none"
            kind = cycle[i % len(cycle)]
            if kind == "ingest_controls":  # a started session sending invalid controls, then a closing message
                fmt = "f32le" if i % 3 == 0 else "pcm_s16le"
                start = json.dumps({"type": "start", "session": f"junk{i}", "sample_rate": RATE, "format": fmt})
                closer = INGEST_CLOSERS[i % len(INGEST_CLOSERS)]
                if fmt == "f32le" and i % 2:
                    closer = np.full(64, np.nan, "<f4").tobytes()  # NaN samples (1007)
                controls = [json.dumps(BAD_CONTROLS[(i + k) % len(BAD_CONTROLS)]) for k in range(20)]
                await conversation("ingest_controls", "/ingest", [start], controls, closer)
            elif kind == "ingest_first":
                await conversation("ingest_first", "/ingest", [], [], FIRST_MESSAGES[i % len(FIRST_MESSAGES)])
            elif kind == "viewer_controls":  # a viewer of a healthy session sending invalid controls, then junk
                controls = [json.dumps(BAD_VIEWER_CONTROLS[(i + k) % len(BAD_VIEWER_CONTROLS)]) for k in range(10)]
                closer = VIEWER_CLOSERS[i % len(VIEWER_CLOSERS)]
                await conversation("viewer_controls", f"/view?session={s}&audio=0", [], controls, closer)
            elif kind == "viewer_query":
                q = BAD_QUERIES[i % len(BAD_QUERIES)].replace("{s}", s)
                await conversation("viewer_query", "/view?" + q, [], [], None)
            else:
                await raw("bad_request", RAW_REQUESTS[i % len(RAW_REQUESTS)].replace("{s}", s))

    async def flood_ingest() -> None:
        pcm = speech_signal(20.0, seed=5).tobytes()
        chunk = pcm[: 2 * RATE * 2]  # 2 s of audio
        n = 0
        while not stop():
            n += 1
            try:
                async with connect(ws_url(url, "/ingest"), compression=None, **local) as ws:
                    await ws.send(json.dumps({"type": "start", "session": f"flood{n}", "sample_rate": RATE}))
                    await ws.recv()
                    while not stop():  # 100x real time: 2 s of audio every 20 ms
                        await ws.send(chunk)
                        tally.flood_audio_s += 2.0
                        await asyncio.sleep(0.02)
            except (OSError, InvalidHandshake, ConnectionClosed):
                await asyncio.sleep(0.1)

    cycle = [k for k in SCENARIO_CYCLE if k in scenarios]
    tasks = [worker(w) for w in range(workers)] if cycle else []
    if "flood" in scenarios:
        tasks.append(flood_ingest())
    await asyncio.gather(*tasks)


def _hostile_proc(
    url: str,
    sessions: list[str],
    go,
    stop,
    counter,
    out,
    local_host: str | None,
    rate_per_s: float | None,
    scenarios: frozenset[str],
) -> None:
    """Child process: wait for ``go``, send hostile traffic until ``stop``, report the tally."""
    tally = HostileTally()

    def count(n: int) -> None:
        with counter.get_lock():
            counter.value += n

    async def main() -> None:
        while not go.is_set():
            await asyncio.sleep(0.05)
        await hostile_traffic(
            url,
            sessions,
            stop=stop.is_set,
            tally=tally,
            on_answer=count,
            local_host=local_host,
            rate_per_s=rate_per_s,
            scenarios=scenarios,
        )

    t0, cpu0 = time.monotonic(), time.process_time()
    asyncio.run(main())
    report = tally.report()
    wall = time.monotonic() - t0
    report["sender_cpu_s"] = round(time.process_time() - cpu0, 1)
    report["sender_wall_s"] = round(wall, 1)
    out.put(report)


def _metrics(url: str) -> dict:
    from urllib.request import urlopen

    with urlopen(url + "/metrics", timeout=30) as r:
        return json.loads(r.read())


def _health(url: str) -> int:
    from urllib.error import URLError
    from urllib.request import urlopen

    try:
        with urlopen(url + "/health", timeout=30) as r:
            return r.status
    except (URLError, OSError):
        return 0


def _run(
    server: ServerProcess,
    model,
    *,
    seconds: float,
    sessions: int,
    viewers: int,
    hostile: bool,
    hostile_messages: int,
    hostile_rate: float | None,
    local_host: str | None,
    scenarios: frozenset[str] = SCENARIOS,
) -> dict:
    """The quiet half (``seconds / 2``), then the hostile half: at least ``seconds / 2`` and until
    ``hostile_messages`` were answered (at most 10x the half; reported if the target was missed).
    ``hostile_rate``: hostile messages a second (None: the target spread over the hostile half;
    0: as fast as the sender goes)."""
    url = server.url
    half_s = seconds / 2
    max_s = half_s + (10 * half_s if hostile else half_s) + 5
    names = [f"soak{s}" for s in range(sessions)]
    clients = ClientProcesses(url, "soak", sessions, sessions * viewers, 0, max_s)
    ctx = mp.get_context("spawn")
    counter, go, stop_hostile, hostile_out = ctx.Value("q", 0), ctx.Event(), ctx.Event(), ctx.Queue()
    hostile_proc = None
    rate = hostile_messages / half_s if hostile_rate is None else (hostile_rate or None)
    if hostile:  # started now (its imports take a second or two), it waits for the half-way mark
        hostile_proc = ctx.Process(
            target=_hostile_proc,
            args=(url, names, go, stop_hostile, counter, hostile_out, local_host, rate, scenarios),
            daemon=True,
        )
        hostile_proc.start()
    clients.wait_viewers()
    t_start = time.monotonic()
    half_wall = time.time() + 0.2 + half_s  # streaming starts 0.2 s after the viewers are ready
    rss: list[tuple[float, float]] = []
    quiet_metrics: dict = {}
    t_half = t_start + 0.2 + half_s
    next_rss = t_start
    hostile_started = None
    health_during: list[int] = []
    while True:
        now = time.monotonic()
        if now >= next_rss:
            rss.append((now - t_start, _rss_mb(server.proc.pid)))
            next_rss += 5.0
            if hostile_started is not None:
                health_during.append(_health(url))
        if not quiet_metrics and now >= t_half:
            quiet_metrics = _metrics(url)
            if hostile:
                go.set()
                hostile_started = now
        if quiet_metrics:
            elapsed = now - t_half
            enough = elapsed >= half_s and (not hostile or counter.value >= hostile_messages)
            if enough or elapsed >= max_s - half_s - 5 or server.proc.poll() is not None:
                break
        if clients.ingest_done():
            break
        time.sleep(0.2)
    t_stop_wall = time.time()
    stop_hostile.set()
    clients.stop()
    tally = None
    if hostile_proc is not None:
        tally = hostile_out.get(timeout=60)
        hostile_proc.join(30)
    ingest = clients.ingest_result(timeout=120)
    views = clients.viewer_result(timeout=120)
    alive = server.proc.poll() is None
    status = _health(url) if alive else 0
    final = _metrics(url) if alive else {}
    rss.append((time.monotonic() - t_start, _rss_mb(server.proc.pid) if alive else float("nan")))

    # End-to-end latency per frame: the send of the block holding the frame's last needed sample
    # to the viewer's receipt; split at the half-way mark.
    mf, d = model.frontend.mfcc, model.frontend.tc
    sent, ended = ingest["sent"], ingest["ended"]
    second = "hostile" if hostile else "second_half"
    e2e: dict[str, list[np.ndarray]] = {"quiet": [], second: []}
    # The same split in two: the block's send to the server's fan-out stamp (the frame header's send
    # time: ingest client, network, the server's loop) and that stamp to the receipt (the write, the
    # viewer process being scheduled), to tell server stalls from client ones.
    to_fanout: dict[str, list[np.ndarray]] = {"quiet": [], second: []}
    to_receipt: dict[str, list[np.ndarray]] = {"quiet": [], second: []}
    per_viewer: list[dict] = []
    lost = 0
    expected = 0
    for _kind, s, _node, idx, received, srv_sent in views:
        n_frames = ended[s] if ended[s] >= 0 else int(len(idx))
        expected += n_frames
        lost += n_frames - len(set(idx.tolist())) if ended[s] >= 0 else 0
        need = np.array([mf.frame_start(int(k) + d) + mf.window_len for k in idx], dtype=np.int64)
        blk = (need - 1) // BLOCK
        ok = blk < sent.shape[1]
        t_need = np.full(len(idx), np.nan)
        t_need[ok] = sent[s, blk[ok]]
        live = ~np.isnan(t_need)
        lat = (received[live] - t_need[live]) * 1e3
        in_quiet = t_need[live] < half_wall
        q, h = lat[in_quiet], lat[~in_quiet]
        e2e["quiet"].append(q)
        e2e[second].append(h)
        fan = (srv_sent[live] - t_need[live]) * 1e3
        rec = (received[live] - srv_sent[live]) * 1e3
        to_fanout["quiet"].append(fan[in_quiet])
        to_fanout[second].append(fan[~in_quiet])
        to_receipt["quiet"].append(rec[in_quiet])
        to_receipt[second].append(rec[~in_quiet])
        per_viewer.append(
            {
                "session": s,
                "quiet_p99_ms": round(float(np.percentile(q, 99)), 3) if q.size else None,
                f"{second}_p99_ms": round(float(np.percentile(h, 99)), 3) if h.size else None,
            }
        )
    summary = {k: summarise(np.concatenate(v) / 1e3) for k, v in e2e.items()}
    warm = next((m for t, m in rss if t >= seconds * 0.1), rss[0][1])
    quiet_rss = next((m for t, m in rss if t >= t_half - t_start), rss[-1][1])
    closes = {
        k: v - quiet_metrics.get("closes", {}).get(k, 0)
        for k, v in final.get("closes", {}).items()
        if v - quiet_metrics.get("closes", {}).get(k, 0)
    }
    out = {
        "rss_mb": {
            "warm": round(warm, 1),
            "end_of_quiet": round(quiet_rss, 1),
            "peak": round(max(m for _, m in rss), 1),
            "end": round(rss[-1][1], 1),
            "growth_percent": round(100 * (rss[-1][1] - warm) / warm, 2),
            "samples": [(round(t, 1), round(m, 1)) for t, m in rss],
        },
        "phases_s": {"quiet": round(half_s, 1), second: round(t_stop_wall - half_wall, 1)},
        "frames_lost": int(lost),
        "frames_expected": int(expected),
        "end_to_end_ms": summary,
        "send_to_server_fanout_ms": {k: summarise(np.concatenate(v) / 1e3) for k, v in to_fanout.items()},
        "server_fanout_to_receipt_ms": {k: summarise(np.concatenate(v) / 1e3) for k, v in to_receipt.items()},
        "per_viewer": per_viewer,
        "loop_lag_p99_ms": {
            "quiet": quiet_metrics.get("timings_ms", {}).get("loop_lag", {}).get("p99_ms"),
            "end": final.get("timings_ms", {}).get("loop_lag", {}).get("p99_ms"),
        },
        # the part of the lag the server's own work can explain (its loop thread's CPU time in the
        # interval); the rest is the process waiting for a core
        "loop_lag_cpu_p99_ms": {
            "quiet": quiet_metrics.get("timings_ms", {}).get("loop_lag_cpu", {}).get("p99_ms"),
            "end": final.get("timings_ms", {}).get("loop_lag_cpu", {}).get("p99_ms"),
        },
        "server_gc_pauses_ms": {  # the server's garbage collections (server.timing.GcPauses), whole run
            k: v for k, v in final.get("timings_ms", {}).items() if k.startswith("gc_gen")
        },
        "ingests_lost": ingest["dropped"],
        "server_closes_second_half": closes,
        "server_alive_at_end": alive,
        "healthy_at_end": status == 200,
    }
    if hostile:
        q99, h99 = summary["quiet"]["p99_ms"], summary["hostile"]["p99_ms"]
        out["hostile"] = {
            "scenarios": sorted(scenarios),
            "target_messages": hostile_messages,
            "paced_at_per_s": None if rate is None else round(rate, 1),
            "target_met": tally is not None and tally["answered"] >= hostile_messages,
            "health_during_hostile": dict(Counter(health_during)),
            **(tally or {}),
        }
        out["p99_hostile_over_quiet"] = round(h99 / q99, 3) if q99 else None
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="facecast bench soak", description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=30.0, help="length of the run (quiet half + hostile half)")
    ap.add_argument("--sessions", type=int, default=4, help="real-time sessions")
    ap.add_argument("--viewers", type=int, default=5, help="parameter viewers per session")
    ap.add_argument("--hostile", action="store_true", help="hostile traffic during the second half")
    ap.add_argument(
        "--hostile-messages",
        type=int,
        default=10000,
        help="the hostile half lasts until this many hostile messages were answered (at least half the run)",
    )
    ap.add_argument(
        "--hostile-rate",
        type=float,
        default=None,
        help="hostile messages a second (default: the target spread over the hostile half; 0: as fast as possible)",
    )
    ap.add_argument(
        "--hostile-scenarios",
        default=",".join(sorted(SCENARIOS)),
        help=f"comma-separated subset of {','.join(sorted(SCENARIOS))} (to find what costs the healthy viewers)",
    )
    ap.add_argument(
        "--hostile-from",
        default="127.0.0.2",
        help="source address of the hostile connections (a loopback alias: a client of its own; '' = default)",
    )
    ap.add_argument("--model", type=Path, default=None, help="model file (default: shipped, else paper-size random)")
    args = ap.parse_args(argv)
    if not set(args.hostile_scenarios.split(",")) <= SCENARIOS:
        ap.error(f"--hostile-scenarios: choose from {','.join(sorted(SCENARIOS))}")
    model, model_path, model_desc = benchmark_model(args.model)
    server = ServerProcess(model_path, head=True)
    load_before = os.getloadavg()
    try:
        result = _run(
            server,
            model,
            seconds=args.minutes * 60,
            sessions=args.sessions,
            viewers=args.viewers,
            hostile=args.hostile,
            hostile_messages=args.hostile_messages,
            hostile_rate=args.hostile_rate,
            scenarios=frozenset(args.hostile_scenarios.split(",")),
            local_host=args.hostile_from or None,
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
