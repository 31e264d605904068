"""Connection workers (server.shards, ``worker_mode = "connections"``): a real front and worker
processes over loopback sockets. Sessions with their ingest and viewer connections run in the
workers; what clients see must be what one process gives them."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import socket

import numpy as np
import pytest

from assets.audio import read_audio
from clients.client import IngestClient, ServerClosed, ViewerClient, http_get, stream_samples
from realtime_core.features.resample import resample_audio
from realtime_core.pipeline import speech_to_params
from tests.live_server import running
from tests.server.test_held_viewers import _until
from tests.server.test_service import _expect_close, _int16, _raw, _start
from tests.speech import speechlike
from wire import protocol as P

pytestmark = [pytest.mark.system, pytest.mark.slow]  # worker processes load the model and kernels

KINDS = [("params", None), ("deltas", "int16"), ("blendshapes", "arkit52")]


@pytest.fixture(autouse=True)
def server_event_loop():
    """These tests run a front of connection workers in their own ``asyncio.run``: on asyncio's loop, as
    ``facecast serve`` runs one (server.eventloop.process_loop; the workers run on the configured loop)."""
    yield


async def _two_sessions(url: str, pcms: list[np.ndarray], rate: int) -> tuple[list[dict], list[list], dict, dict]:
    """Sessions s0, s1 streamed at once, each watched by a viewer of every kind in KINDS (with audio);
    returns the ingests' end replies, each session's viewers' results, /sessions and /metrics while
    they ran."""

    async def one(j: int, pcm: np.ndarray, ready: asyncio.Event, go: asyncio.Event):
        async with IngestClient(url, session=f"s{j}", sample_rate_hz=rate) as ing:
            viewers = [ViewerClient(url, session=f"s{j}", kind=k, encoding=e, audio=True) for k, e in KINDS]
            for v in viewers:
                await v.__aenter__()
            tasks = [asyncio.ensure_future(v.collect()) for v in viewers]
            ready.set()
            await go.wait()
            await stream_samples(ing, pcm, realtime=False, block_s=0.02)
            ended = await ing.end()
            results = await asyncio.gather(*tasks)
            for v in viewers:
                await v.__aexit__(None, None, None)
        return ended, results

    ready = [asyncio.Event(), asyncio.Event()]
    go = asyncio.Event()
    runs = [asyncio.ensure_future(one(j, pcm, ready[j], go)) for j, pcm in enumerate(pcms)]
    await asyncio.gather(*(r.wait() for r in ready))
    status, body = await http_get(url, "/sessions")
    assert status == 200
    sessions = json.loads(body)
    status, body = await http_get(url, "/metrics")
    assert status == 200
    metrics = json.loads(body)
    go.set()
    out = await asyncio.gather(*runs)
    return [e for e, _ in out], [r for _, r in out], sessions, metrics


def test_connection_workers_give_the_frames_of_one_process(model, head, wav48k):
    """The same two sessions and viewers, one process vs. a front with two connection workers: every
    message of every viewer is byte-identical (frames and audio), and equals `facecast animate`."""
    samples, rate = read_audio(wav48k)
    pcm = _int16(samples)
    other = _int16(speechlike(1.2, rate, seed=3))
    ref = speech_to_params(model, resample_audio(samples, rate, model.sample_rate_hz))

    async def main(**config):
        async with running(model, head, **config) as srv:
            out = await _two_sessions(srv.url, [pcm, other], rate)
            owners = None if srv.shards is None else sorted(s.slot for s in srv.shards.owner.values())
            return out, owners

    (ended1, got1, _, _), _ = asyncio.run(main())
    (ended2, got2, sessions, metrics), owners = asyncio.run(main(workers=2, worker_mode="connections"))
    assert owners == []  # both released when they ended
    assert ended1 == ended2 and ended2[0]["frames"] == len(ref)
    for a_views, b_views in zip(got1, got2):
        for a, b in zip(a_views, b_views):
            assert len(a.frames) == len(b.frames) > 0 and len(a.audio) == len(b.audio) > 0
            for x, y in zip(a.frames + a.audio, b.frames + b.audio):
                assert (x.kind, x.encoding, x.index, x.media_time) == (y.kind, y.encoding, y.index, y.media_time)
                np.testing.assert_array_equal(x.values, y.values)
            assert a.close_code == b.close_code == P.CLOSE_NORMAL
    np.testing.assert_allclose(got2[0][0].values(), ref, atol=1e-6)  # params are float32 on the wire
    # While both ran: the front listed both sessions (each from its worker), with their viewers.
    rows = {r["name"]: r for r in sessions["sessions"]}
    assert sorted(rows) == ["s0", "s1"] and all(r["viewers"] == len(KINDS) for r in rows.values())
    assert metrics["sessions"] == 2 and metrics["viewers"] == 2 * len(KINDS)
    assert sorted(w["sessions"] for w in metrics["workers"]) == [1, 1]  # one per worker


@pytest.mark.parametrize("worker_loop", ["uvloop", "asyncio"])
def test_bad_clients_close_one_connection_and_names_stay_unique(model, worker_loop):
    """A malformed message closes that connection with its code and reason; a message over
    max_message_bytes gets 1009 (the adopted connection has the listener's limits); a session name
    taken on one worker is refused on the other; a viewer of no session gets 4004; the healthy
    session loses no frame. Workers on either loop (each adopts the connections the front hands it)."""
    pcm = _int16(speechlike(2.0, 16000, seed=5))

    async def main():
        async with running(
            model, workers=2, worker_mode="connections", event_loop=worker_loop, max_message_bytes=1 << 16
        ) as srv:
            url = srv.url
            async with IngestClient(url, session="dup", sample_rate_hz=16000) as ing:
                async with ViewerClient(url, session="dup", audio=False) as view:
                    collect = asyncio.ensure_future(view.collect())
                    feed = asyncio.ensure_future(stream_samples(ing, pcm, realtime=True))
                    # Ingests go round-robin over equally loaded workers: this one lands on the other.
                    taken = await _expect_close(
                        lambda: IngestClient(url, session="dup", sample_rate_hz=16000).__aenter__()
                    )
                    garbage = await _expect_close(
                        lambda: _raw(url, "/ingest", _start(session="g", token=None), b"\x01\x02\x03")
                    )
                    nobody = await _expect_close(lambda: ViewerClient(url, session="nobody").__aenter__())
                    big = await _expect_close(lambda: _raw(url, "/ingest", b"\x00" * 70000))
                    await feed
                    ended = await ing.end()
                    got = await collect
            status, body = await http_get(url, "/health")
            return taken, garbage, nobody, big, ended, got, status, json.loads(body)

    taken, garbage, nobody, big, ended, got, status, health = asyncio.run(main())
    assert taken[0] == P.CLOSE_CONFLICT and "already exists" in taken[1]
    assert garbage[0] == P.CLOSE_INVALID_PAYLOAD and "not a whole number" in garbage[1]
    assert nobody[0] == P.CLOSE_NOT_FOUND
    assert big[0] == P.CLOSE_TOO_BIG
    assert [m.index for m in got.frames] == list(range(ended["frames"])) and ended["frames"] > 50
    assert status == 200 and health["status"] == "ok" and health["sessions"] == 0


def test_a_dead_worker_ends_its_sessions_only(model):
    """Killing a worker ends the sessions it ran (their clients see the connection drop); the front
    stays up, frees the names, starts a new worker, and a session elsewhere goes on untouched."""
    pcm = _int16(speechlike(3.0, 16000, seed=7))

    async def main():
        async with running(model, workers=2, worker_mode="connections", close_timeout_s=0.5) as srv:
            url = srv.url
            assert srv.shards is not None
            a = await IngestClient(url, session="a", sample_rate_hz=16000).__aenter__()
            b = await IngestClient(url, session="b", sample_rate_hz=16000).__aenter__()
            va = await ViewerClient(url, session="a", audio=False).__aenter__()
            vb = await ViewerClient(url, session="b", audio=False).__aenter__()
            ca, cb = asyncio.ensure_future(va.collect()), asyncio.ensure_future(vb.collect())
            fb = asyncio.ensure_future(stream_samples(b, pcm, realtime=True))
            fa = asyncio.ensure_future(stream_samples(a, pcm, realtime=True))
            await asyncio.sleep(0.5)
            victim = srv.shards.owner["a"]
            assert srv.shards.owner["b"] is not victim
            os.kill(victim.proc.pid, signal.SIGKILL)
            got_a = await asyncio.wait_for(ca, 10)
            try:
                await fa
                a_failed = False
            except (ServerClosed, ConnectionError, OSError):
                a_failed = True
            except Exception as exc:  # noqa: BLE001 - any connection error of the client library
                a_failed = "ConnectionClosed" in type(exc).__name__
            while srv.shards.owns("a") or not all(s.ready.done() for s in srv.shards.shards):
                await asyncio.sleep(0.05)
            # The name is free again; the new session lands on the replacement worker or the other one.
            async with IngestClient(url, session="a", sample_rate_hz=16000) as again:
                await stream_samples(again, pcm[:16000], realtime=False)
                again_ended = await again.end()
            await fb
            b_ended = await b.end()
            got_b = await cb
            status, _ = await http_get(url, "/health")
            return got_a, a_failed, again_ended, b_ended, got_b, status

    got_a, a_failed, again_ended, b_ended, got_b, status = asyncio.run(main())
    assert got_a.close_code is None  # no close frame: the connection dropped with its process
    assert a_failed and again_ended["frames"] == 30 and status == 200
    assert [m.index for m in got_b.frames] == list(range(b_ended["frames"])) and b_ended["frames"] == 90


def test_a_viewer_held_by_the_front_of_connection_workers_watches_a_session_opened_in_a_worker(model, caplog):
    """With connection workers an audio session runs in a worker: a viewer held by the front (which received it
    before the session existed) is told to connect again when a worker takes the session's name, and the python
    viewer does so at once: it watches the session, from frame 0. The hand-off is normal operation: one INFO line
    saying so, not "closed a client connection: 4004 ..." (a client error) per viewer."""
    import logging

    caplog.set_level(logging.DEBUG, logger="facecast")
    from clients.viewer.stream import ViewerStreamConfig, record_stream

    pcm = _int16(speechlike(1.0, 16000, seed=6))

    async def main():
        async with running(model, workers=1, worker_mode="connections") as srv:
            url = srv.url
            cfg = ViewerStreamConfig(url=url, session="w", kind="params", wait_s=20)
            rec = asyncio.ensure_future(record_stream(cfg))
            await _until(lambda: len(srv.holds) == 1, "the viewer held by the front")
            async with IngestClient(url, session="w", sample_rate_hz=16000) as ing:
                for _ in range(400):  # the viewer, told to connect again, watches in the worker (at most 20 s)
                    metrics = await srv._metrics_all()
                    if metrics["viewers"] == 1 and not srv.holds:
                        break
                    await asyncio.sleep(0.05)
                await stream_samples(ing, pcm, realtime=False, block_s=0.02)
                ended = await ing.end()
            return ended, await rec

    ended, rec = asyncio.run(asyncio.wait_for(main(), 90))
    assert rec.index == list(range(ended["frames"])) and rec.close_code == P.CLOSE_NORMAL
    assert sum(len(b) for _, b in rec.audio) == len(pcm)
    told = [r for r in caplog.records if "connect again" in r.getMessage()]
    assert [(r.name, r.levelno) for r in told] == [("facecast.shards", logging.INFO)], caplog.text
    assert "session 'w' opened in connection worker 0: 1 viewer(s) held for it told to connect again" in told[0].message
    assert not [r for r in caplog.records if "closed a client connection" in r.getMessage()], caplog.text


def test_request_line_is_peeked_whole_or_not_at_all():
    """The front reads a new connection's request line without consuming it: whole when it comes in
    pieces, None when the peer hangs up first, is too long or too slow."""
    from server.shards import MAX_REQUEST_LINE, _request_line

    async def main():
        out = []
        for pieces, timeout in (
            ([b"GET /view?ses", b"sion=a HTTP/1.1\r\nHost: x\r\n\r\n"], 5.0),
            ([b"GET /ingest HTTP/1.1"], 0.3),  # never finished
            ([b"G" * (MAX_REQUEST_LINE + 10)], 5.0),
            ([], 5.0),  # hangs up
        ):
            a, b = socket.socketpair()
            a.setblocking(False)
            b.setblocking(False)

            async def send(b=b, pieces=pieces):
                for p in pieces:
                    b.sendall(p)
                    await asyncio.sleep(0.05)
                if not pieces:
                    b.close()

            sender = asyncio.ensure_future(send())
            line = await _request_line(a, timeout)
            await sender
            rest = a.recv(1 << 16) if line is not None else b""
            out.append((line, rest))
            a.close()
            b.close()
        return out

    (line, rest), (slow, _), (long, _), (gone, _) = asyncio.run(main())
    assert line == b"GET /view?session=a HTTP/1.1" and rest.startswith(line + b"\r\nHost: x")  # not consumed
    assert slow is None and long is None and gone is None
