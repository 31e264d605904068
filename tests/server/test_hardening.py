"""Hardening over real sockets: Origin and Host checks, the token on HTTP, ingest pacing and its
close mode, batch sessions, idle timeout, per-client limits, hostile JSON and paths."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections import Counter

import numpy as np
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from clients.client import IngestClient, ServerClosed, ViewerClient, http_get, ws_url
from server.app import FacecastServer
from server.config import ServerConfig
from tests.live_server import running
from tests.speech import speechlike
from wire import protocol as P

# A real server over loopback sockets.
pytestmark = pytest.mark.system


async def raw_http(port: int, request: bytes) -> tuple[int, bytes]:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(request)
    await writer.drain()
    data = await asyncio.wait_for(reader.read(), 10)
    writer.close()
    head, _, body = data.partition(b"\r\n\r\n")
    return int(head.split(b" ", 2)[1]), body


async def handshake_status(url: str, path: str, **kw) -> int | None:
    """HTTP status of a refused WebSocket handshake (None: accepted)."""
    try:
        async with connect(ws_url(url, path), compression=None, **kw):
            return None
    except InvalidStatus as exc:
        return exc.response.status_code


def _pcm(seconds: float) -> np.ndarray:
    return np.rint(speechlike(seconds, 16000) * 32767).astype(np.int16)


def test_origin_host_and_token_checks(model):
    async def main():
        async with running(model, token="sesame", allowed_origins=["http://app.example"]) as srv:
            url, port = srv.url, srv.port
            async with IngestClient(url, session="s", sample_rate_hz=16000, token="sesame"):
                view = "/view?session=s&token=sesame"
                origins = {
                    o: await handshake_status(url, view, origin=o)
                    for o in (None, f"http://127.0.0.1:{port}", "http://app.example", "http://evil.example", "null")
                }
                status = {}
                for path in (
                    "/health",
                    "/metrics",
                    "/sessions",
                    "/head/mesh",
                    "/",
                    "/metrics?token=nope",
                    "/metrics?token=sesame",
                    "/sessions?token=sesame",
                ):
                    status[path] = await http_get(url, path)
                bearer = await raw_http(
                    port,
                    b"GET /sessions HTTP/1.1\r\nHost: localhost\r\n"
                    b"Authorization: Bearer sesame\r\nConnection: close\r\n\r\n",
                )
                rebound = await raw_http(
                    port, b"GET /health HTTP/1.1\r\nHost: evil.example\r\nConnection: close\r\n\r\n"
                )
                rebound_ws = await raw_http(
                    port,
                    b"GET /view?session=s&token=sesame HTTP/1.1\r\nHost: evil.example\r\n"
                    b"Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: "
                    b"dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
                )
                return origins, status, bearer, rebound, rebound_ws

    origins, status, bearer, rebound, rebound_ws = asyncio.run(main())
    assert list(origins.values()) == [None, None, None, 403, 403]
    assert status["/health"][0] == 200 and b'"s"' not in status["/health"][1]
    for path in ("/metrics", "/sessions", "/head/mesh", "/metrics?token=nope"):
        assert status[path][0] == 401, path
    assert status["/"][0] == 200 and b"token" in status["/"][1] and b">s<" not in status["/"][1]
    assert status["/metrics?token=sesame"][0] == 200
    assert json.loads(status["/sessions?token=sesame"][1])["sessions"][0]["name"] == "s"
    assert bearer[0] == 200
    assert rebound[0] == 403 and rebound_ws[0] == 403


def test_file_paths_never_reach_a_client(model, tmp_path):
    async def blocks():
        yield np.zeros(1600, np.float32)
        await asyncio.sleep(10)

    async def main():
        async with running(model) as srv:
            task = asyncio.ensure_future(
                srv.run_source("f", blocks(), sample_rate_hz=16000, label=f"file {tmp_path}/secret/take1.wav")
            )
            while "f" not in srv.sessions:
                await asyncio.sleep(0.01)
            out = [await http_get(srv.url, p) for p in ("/metrics", "/sessions", "/")]
            task.cancel()
            return out

    for status, body in asyncio.run(main()):
        assert status == 200 and b"secret" not in body and str(tmp_path).encode() not in body


def test_ingest_is_paced_to_real_time_after_its_burst_or_closed_or_batch(model):
    pcm = _pcm(2.0)

    async def send_all(url):
        async with IngestClient(url, session="fast", sample_rate_hz=16000) as ing:
            t0 = time.monotonic()
            for i in range(0, len(pcm), 1600):
                await ing.send(pcm[i : i + 1600])
            ended = await ing.end()
            return time.monotonic() - t0, ended

    async def batch(url):
        async with connect(ws_url(url, "/ingest"), compression=None) as ws:
            await ws.send(json.dumps({"type": "start", "session": "b", "sample_rate": 16000, "batch": True}))
            json.loads(await ws.recv())
            t0 = time.monotonic()
            await ws.send(pcm.tobytes())
            await ws.send(json.dumps({"type": "end"}))
            ended = json.loads(await ws.recv())
            return time.monotonic() - t0, ended

    async def main():
        async with running(model, ingest_burst_s=0.5) as srv:
            paced = await send_all(srv.url)
            fast = await batch(srv.url)
        async with running(model, ingest_burst_s=0.5, ingest_overrun="close") as srv:
            try:
                await send_all(srv.url)
                closed = None
            except ServerClosed as exc:
                closed = (exc.code, exc.reason)
        return paced, fast, closed

    (paced_s, ended), (batch_s, batch_ended), closed = asyncio.run(main())
    assert paced_s >= 1.4 and ended["frames"] == batch_ended["frames"] > 0  # 2 s of audio, 0.5 s ahead at most
    assert batch_s < paced_s
    assert closed is not None and closed[0] == P.CLOSE_TOO_FAST and "ahead of real time" in closed[1]


def test_idle_timeout_and_per_client_limit(model):
    async def main():
        async with running(model, idle_timeout_s=0.3, max_connections_per_client=2) as srv:
            url = srv.url
            try:
                async with IngestClient(url, session="idle", sample_rate_hz=16000) as ing:
                    async with ViewerClient(url, session="idle"):
                        third = await handshake_status(url, "/view?session=idle")
                        await asyncio.sleep(1.0)
                        await ing.send(np.zeros(160, np.int16))
                        await ing.end()
                idle = None
            except ServerClosed as exc:
                idle = (exc.code, exc.reason)
            return third, idle

    third, idle = asyncio.run(main())
    assert third == 429
    assert idle is not None and idle[0] == P.CLOSE_POLICY and "idle" in idle[1]


def test_hostile_json_and_paths_are_refused_without_internal_errors(model, caplog):
    deep = "[" * 30000 + "]" * 30000

    async def one(url, *msgs):
        async with connect(ws_url(url, "/ingest"), compression=None, max_size=None) as ws:
            for m in msgs:
                await ws.send(m)
            with contextlib.suppress(Exception):
                while True:
                    await asyncio.wait_for(ws.recv(), 5)
            return ws.close_code, ws.close_reason

    async def main():
        async with running(model) as srv:
            start = json.dumps({"type": "start", "session": "h", "sample_rate": 16000})
            out = [await one(srv.url, deep) for _ in range(20)]
            out.append(await one(srv.url, start, '{"type": "control", "gain": ' + deep + "}"))
            long_path = await http_get(srv.url, "/" + "a" * 5000)
            long_name = await http_get(srv.url, "/" + "b" * 300)
            health = await http_get(srv.url, "/health")
            return out, long_path, long_name, health, srv.metrics()

    with caplog.at_level(logging.INFO, logger="facecast.server"):
        out, long_path, long_name, health, metrics = asyncio.run(main())
    assert all(code == P.CLOSE_INVALID_PAYLOAD and "nests deeper" in reason for code, reason in out)
    assert long_path[0] in (404, 414) and long_name[0] in (404, 414)
    assert health[0] == 200
    assert "1011" not in metrics["closes"]
    messages = [r.getMessage() for r in caplog.records if r.name == "facecast.server"]
    assert not any(r.exc_info for r in caplog.records)
    assert len(messages) <= 4, messages  # 21 refusals: logged once per kind, not once each


@pytest.mark.parametrize(
    "cfg, match",
    [
        ({"ingest_overrun": "drop"}, "ingest_overrun"),
        ({"allowed_origins": ["null"]}, "null"),
        ({"allowed_origins": "http://a"}, "allowed_origins"),
        ({"max_connections_per_client": -1}, "max_connections_per_client"),
    ],
)
def test_bad_hardening_config_is_named(cfg, match):
    from server.errors import ServerConfigError

    with pytest.raises(ServerConfigError, match=match):
        ServerConfig(**cfg)


def test_shutdown_does_not_wait_for_a_paced_backlog(model):
    pcm = _pcm(1.0)

    async def main():
        srv = FacecastServer(model, config=ServerConfig(port=0, ingest_burst_s=0.2, close_timeout_s=1.0))
        await srv.start()
        ws = await connect(ws_url(srv.url, "/ingest"), compression=None)
        await ws.send(json.dumps({"type": "start", "session": "flood", "sample_rate": 16000}))
        await ws.recv()

        async def flood():  # 100x real time: the server paces it, a backlog builds up
            with contextlib.suppress(Exception):
                for _ in range(40):
                    await ws.send(pcm.tobytes())
                    await asyncio.sleep(0.01)

        task = asyncio.ensure_future(flood())
        await asyncio.sleep(1.0)
        t0 = time.monotonic()
        await asyncio.wait_for(srv.stop(), 15)
        took = time.monotonic() - t0
        task.cancel()
        return took, ws.close_code

    took, code = asyncio.run(main())
    assert took < 5.0 and code == P.CLOSE_GOING_AWAY


def test_connection_churn_neither_delays_nor_loses_a_healthy_viewers_frames(model):
    """A client opening and closing WebSocket connections in a loop (from its own loopback address)
    while a session streams in real time: past its burst it is refused with the documented 429 (never
    anything else), its accepted connections fit the token bucket, and the healthy viewer receives
    every frame, in order, never more than MAX_BEHIND frames behind the audio the ingest had sent
    (counts of frames, not a timing: a loop stalled by handshakes would let the backlog grow)."""
    rate_per_s, burst = 20.0, 10
    block, n_blocks = 320, 150  # 20 ms blocks, 3 s of audio
    max_behind = 15  # frames (0.5 s) beyond the algorithmic delay
    pcm = _pcm(n_blocks * block / 16000)

    async def churn(url: str, stop: asyncio.Event, tally: dict) -> None:
        paths = ["/view?session=calm&audio=0", "/view?session=nobody"]
        i = 0
        while not stop.is_set():
            i += 1
            try:
                async with connect(ws_url(url, paths[i % 2]), compression=None, local_addr=("127.0.0.2", 0)) as ws:
                    tally["accepted"] += 1
                    await ws.recv()  # the description (then the client hangs up) or the 4004 close
            except InvalidStatus as exc:
                tally["status"][exc.response.status_code] += 1
                tally["reasons"].add(exc.response.body.decode().strip())
            except ConnectionClosed:
                pass
            await asyncio.sleep(0)

    async def main():
        async with running(model, connect_rate_per_s=rate_per_s, connect_burst=burst) as srv:
            url = srv.url
            tally: dict = {"accepted": 0, "reasons": set(), "status": Counter()}
            sent_frames = 0.0
            behind: list[float] = []
            async with IngestClient(url, session="calm", sample_rate_hz=16000) as ing:
                delay_frames = ing.started["algorithmic_delay_s"] * 30
                async with ViewerClient(url, session="calm", audio=False) as viewer:

                    async def watch() -> list[int]:
                        got = []
                        async for m in viewer:
                            got.append(m.index)
                            behind.append(sent_frames - delay_frames - m.index)
                        return got

                    watcher = asyncio.ensure_future(watch())
                    stop = asyncio.Event()
                    t0 = time.monotonic()
                    churner = asyncio.ensure_future(churn(url, stop, tally))
                    loop = asyncio.get_running_loop()
                    start = loop.time()
                    for i in range(n_blocks):  # real time on an absolute schedule
                        await asyncio.sleep(max(0.0, start + i * block / 16000 - loop.time()))
                        await ing.send(pcm[i * block : (i + 1) * block])
                        sent_frames = (i + 1) * block / 16000 * 30
                    stop.set()
                    await churner
                    elapsed = time.monotonic() - t0
                    ended = await ing.end()
                    got = await asyncio.wait_for(watcher, 30)
            return tally, elapsed, ended["frames"], got, behind

    tally, elapsed, n_frames, got, behind = asyncio.run(main())
    assert set(tally["status"]) == {429}  # refused past the burst, with 429 and nothing else
    assert all("too many new connections" in r for r in tally["reasons"])
    assert tally["accepted"] <= burst + rate_per_s * elapsed + 1  # the token bucket's bound
    assert got == list(range(n_frames)) and n_frames > 80  # nothing accepted is lost, in order
    assert max(behind) <= max_behind, f"the healthy viewer fell {max(behind):.1f} frames behind"


def test_numbers_out_of_range_are_refused_in_short_reasons_and_the_session_goes_on(model):
    """Controls with absurd numbers over a real socket: each is answered "rejected" with the number in %.6g
    form (an expression at 1e300 was quoted with 300 digits), a JSON integer beyond a float's range too (it
    raised OverflowError/TypeError: an internal error, close 1011), and the session streams on to its end."""
    huge = "1" + "0" * 400  # a JSON integer no float holds
    controls = [
        (text.replace("HUGE", huge), number)
        for text, number in [
            ('{"type": "control", "expression": {"name": "smile", "at": 1e300}}', "1e+300"),
            ('{"type": "control", "expression": {"name": "smile", "at": -1e300}}', "-1e+300"),
            ('{"type": "control", "expression": {"name": "smile", "at": HUGE}}', "1.00000e+400"),
            ('{"type": "control", "expression": {"name": "smile", "intensity": HUGE}}', "1.00000e+400"),
            ('{"type": "control", "gain": {"mouth_open": HUGE}}', "1.00000e+400"),
            ('{"type": "control", "smoothing_ms": -HUGE}', "-1.00000e+400"),
            ('{"type": "control", "expression_ease_s": 1e300}', "1e+300"),
        ]
    ]

    async def main():
        async with running(model) as srv, connect(ws_url(srv.url, "/ingest"), compression=None) as ws:
            await ws.send(json.dumps({"type": "start", "session": "n", "sample_rate": 16000}))
            assert json.loads(await ws.recv())["type"] == "started"
            await ws.send(_pcm(0.5).tobytes())
            replies = []
            for text, _ in controls:
                await ws.send(text)
                replies.append(json.loads(await ws.recv()))
            await ws.send(json.dumps({"type": "control", "expression": {"name": "smile", "at": 3}}))  # an int: fine
            replies.append(json.loads(await ws.recv()))
            await ws.send(json.dumps({"type": "end"}))
            ended = json.loads(await ws.recv())
            await ws.wait_closed()
            return replies, ended, ws.close_code, srv.metrics()

    replies, ended, code, metrics = asyncio.run(asyncio.wait_for(main(), 60))
    for (text, number), reply in zip(controls, replies):
        assert reply["type"] == "rejected", (text[:60], reply)
        assert number in reply["reason"] and len(reply["reason"]) < 120, reply["reason"]
    assert replies[-1]["type"] == "ack" and replies[-1]["controls"]["expression"][-1]["at"] == 3.0
    assert ended["type"] == "ended" and ended["frames"] > 0 and code == P.CLOSE_NORMAL
    assert "1011" not in metrics["closes"]


@pytest.mark.parametrize("peak, accepted", [(2.0, True), (-2.0, True), (2.001, False), (5.0, False), (32767.0, False)])
def test_f32le_samples_beyond_the_peak_limit_close_with_1007(model, peak, accepted):
    """docs/protocol.md sections 2 and 5: f32le is float audio at full scale 1 with headroom to +-2 (+6 dBFS,
    a float mix's or resampler's overshoot); a block with a sample beyond it closes the ingest with 1007 and
    a reason quoting it. 5.0 was accepted (the limit was 64) while the reason said [-1, 1]."""
    from server.session import F32_PEAK_MAX

    assert F32_PEAK_MAX == 2.0
    block = (speechlike(0.5, 16000) * 0.5).astype("<f4")
    block[4000] = peak

    async def main():
        async with running(model) as srv, connect(ws_url(srv.url, "/ingest"), compression=None) as ws:
            await ws.send(json.dumps({"type": "start", "session": "f", "sample_rate": 16000, "format": "f32le"}))
            assert json.loads(await ws.recv())["type"] == "started"
            await ws.send(block.tobytes())
            with contextlib.suppress(ConnectionClosed):
                await ws.send(json.dumps({"type": "end"}))
            with contextlib.suppress(ConnectionClosed):
                while True:
                    last = json.loads(await ws.recv())
            await ws.wait_closed()
            return last if accepted else None, ws.close_code, ws.close_reason

    last, code, reason = asyncio.run(asyncio.wait_for(main(), 60))
    if accepted:
        assert code == P.CLOSE_NORMAL and last["type"] == "ended" and last["frames"] > 0
    else:
        assert code == P.CLOSE_INVALID_PAYLOAD
        assert reason == f"f32le samples must be in [-1, 1] (peaks up to 2 pass), got {float(np.float32(peak)):.6g}"
