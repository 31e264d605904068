"""A cluster of three real facecast processes sharing a real redis-server on a loopback port.

A viewer on node B receives exactly what a viewer on node A receives; killing an edge node makes
its viewers reconnect to another without the session noticing; Redis going away shows on /health,
local sessions go on, and the nodes re-register when it returns; a wrong Redis address is one line
at start. Every wait is bounded: nothing hangs.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Coroutine, Iterable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import pytest
from websockets.asyncio.client import connect

from benchmarks.server_harness import ServerProcess
from clients.client import IngestClient, ServerClosed, ViewerClient, http_get, stream_samples, ws_url
from tests.prerequisites import missing
from tests.speech import speechlike
from wire import protocol as P

T = TypeVar("T")

# Three facecast processes and a real redis-server.
pytestmark = [pytest.mark.system, pytest.mark.slow]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class RedisServer:
    """redis-server on 127.0.0.1:port, no persistence; stop() and start() again on the same port."""

    def __init__(self, binary: str, port: int) -> None:
        self.binary, self.port = binary, port
        self.url = f"redis://127.0.0.1:{port}/0"
        self.proc: subprocess.Popen | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen(
            [
                self.binary,
                "--port",
                str(self.port),
                "--bind",
                "127.0.0.1",
                "--save",
                "",
                "--appendonly",
                "no",
                "--protected-mode",
                "no",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2) as c:
                    c.sendall(b"PING\r\n")
                    if c.recv(16).startswith(b"+PONG"):
                        return
            except OSError:
                time.sleep(0.05)
        raise RuntimeError("redis-server did not start within 10 s")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(10)


@pytest.fixture()
def redis_server():
    binary = shutil.which("redis-server") or (
        "/usr/bin/redis-server" if Path("/usr/bin/redis-server").exists() else None
    )
    if binary is None:
        missing("redis-server is not installed (apt-get install redis-server; scripts/setup.sh does it)")
    r = RedisServer(binary, _free_port())
    r.start()
    try:
        yield r
    finally:
        r.stop()


def _node(model_path, redis_url: str, name: str, role: str = "both", args: tuple[str, ...] = ()) -> ServerProcess:
    toml = (
        f'[server]\nredis_url = "{redis_url}"\nnode_id = "{name}"\nheartbeat_s = 0.2\nclose_timeout_s = 1.0\n'
        f'role = "{role}"\n'
    )
    return ServerProcess(model_path, head=False, config_toml=toml, args=args)


def _run_then_stop(nodes: Iterable[ServerProcess], main: Coroutine[Any, Any, T], timeout_s: float) -> T:
    """``main`` run on a fresh event loop (at most ``timeout_s``), then every node stopped, whatever happened."""
    try:
        return asyncio.run(asyncio.wait_for(main, timeout_s))
    finally:
        for n in nodes:
            n.stop()


async def _get_json(url: str, path: str) -> dict:
    status, body = await http_get(url, path)
    assert status == 200, (path, status, body[:200])
    return json.loads(body)


async def _until(predicate, timeout_s: float = 10.0, what: str = "condition"):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = await predicate()
        if value:
            return value
        await asyncio.sleep(0.05)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


async def _published(url: str, name: str, kinds: set[tuple[int, int]]) -> bool:
    rows = (await _get_json(url, "/sessions"))["sessions"]
    row = next((r for r in rows if r["name"] == name), None)
    return row is not None and kinds <= {tuple(k) for k in row.get("published_kinds", [])}


def test_viewers_on_any_node_get_the_same_frames(model_path, redis_server):
    nodes = [_node(model_path, redis_server.url, n) for n in ("a", "b", "c")]
    pcm = np.rint(speechlike(2.0, 16000, seed=4) * 32767).astype(np.int16)

    async def main():
        a, b, c = (n.url for n in nodes)
        async with IngestClient(a, session="x", sample_rate_hz=16000) as ing:
            # Cluster-wide registry: every node lists the session, owned by a.
            for u in (a, b, c):
                rows = (await _until(lambda u=u: _get_json(u, "/sessions"), what="sessions"))["sessions"]
                assert [(r["name"], r["node"]) for r in rows] == [("x", "a")]
            va = ViewerClient(a, session="x", audio=True)
            vb = ViewerClient(b, session="x", audio=True)
            vc = ViewerClient(c, session="x", kind="blendshapes", encoding="arkit52", audio=False)
            for v in (va, vb, vc):
                await v.__aenter__()
            assert vb.description["fps"] == va.description["fps"] and vb.description["session"] == "x"
            await _until(
                lambda: _published(
                    a,
                    "x",
                    {(P.KIND_PARAMS, P.ENC_FLOAT32), (P.KIND_AUDIO, P.ENC_INT16), (P.KIND_ARKIT52, P.ENC_FLOAT32)},
                ),
                what="wants reach the owner",
            )
            tasks = [asyncio.ensure_future(v.collect()) for v in (va, vb, vc)]
            await stream_samples(ing, pcm, realtime=True, block_s=0.02)
            ended = await ing.end()
            got = await asyncio.wait_for(asyncio.gather(*tasks), 20)
        health = [await _get_json(u, "/health") for u in (a, b, c)]
        return ended, got, health

    ended, (ga, gb, gc), health = _run_then_stop(nodes, main(), 90)
    n = ended["frames"]
    assert [m.index for m in ga.frames] == [m.index for m in gb.frames] == list(range(n))
    np.testing.assert_array_equal(gb.values(), ga.values())  # the same bytes decoded: identical
    assert [m.send_time for m in gb.frames] == [m.send_time for m in ga.frames]  # the owner's stamps
    np.testing.assert_array_equal(gb.audio_samples(), ga.audio_samples())
    assert len(gc.frames) == n and gc.values().shape[1] == 52
    assert ga.close_code == gb.close_code == gc.close_code == P.CLOSE_NORMAL
    assert all(h["status"] == "ok" and h["redis"] == "ok" for h in health)
    # The far node's delivery is close behind the near node's (reported, not a goal of this test).
    lag = np.array(gb.received) - np.array(ga.received)
    print(
        f"cluster: far-node minus near-node receipt, median {np.median(lag) * 1e3:.2f} ms, "
        f"p99 {np.percentile(lag, 99) * 1e3:.2f} ms"
    )


def test_a_viewer_held_on_one_node_watches_a_session_opened_on_another(model_path, redis_server):
    """A viewer asking to wait (view query ``wait``) for a session not yet started is held by its node; the
    session opens on another node, which wakes nobody there: the held viewer finds it in the registry (looked up
    every CLUSTER_HOLD_POLL_S while held) and watches it through the cluster, to its end. (Held only for sessions
    of its own node, it would have waited its whole wait and got 4004.) The owner publishes a kind once a node
    wants it, so the audio is streamed here once b's wants have reached a."""
    nodes = [_node(model_path, redis_server.url, n) for n in ("a", "b")]
    pcm = np.rint(speechlike(1.0, 16000, seed=8) * 32767).astype(np.int16)

    async def main():
        a, b = (n.url for n in nodes)
        vb = ViewerClient(b, session="later", audio=True, wait_s=30)
        joined = asyncio.ensure_future(vb.__aenter__())
        await _until(lambda: _held(b, 1), what="the viewer held on b")
        async with IngestClient(a, session="later", sample_rate_hz=16000) as ing:
            await asyncio.wait_for(joined, 10)
            await _until(
                lambda: _published(a, "later", {(P.KIND_PARAMS, P.ENC_FLOAT32), (P.KIND_AUDIO, P.ENC_INT16)}),
                what="b's wants reach the owner",
            )
            got = asyncio.ensure_future(vb.collect())
            await stream_samples(ing, pcm, realtime=False, block_s=0.02)
            ended = await ing.end()
            rec = await asyncio.wait_for(got, 20)
        held_after = (await _get_json(b, "/metrics"))["viewers_held"]
        return ended, rec, held_after

    ended, rec, held_after = _run_then_stop(nodes, main(), 90)
    assert [m.index for m in rec.frames] == list(range(ended["frames"]))
    assert len(rec.audio_samples()) == len(pcm) and rec.close_code == P.CLOSE_NORMAL
    assert held_after == 0


async def _held(url: str, n: int) -> bool:
    return (await _get_json(url, "/metrics"))["viewers_held"] == n


async def _same_rows_with(urls: Iterable[str], name: str, viewers: int) -> list[dict] | None:
    """Session ``name``'s /sessions row as each node in ``urls`` lists it, when every node lists the same row
    (whole JSON) and it counts ``viewers``; else None."""
    rows = []
    for u in urls:
        rows += [r for r in (await _get_json(u, "/sessions"))["sessions"] if r["name"] == name]
    return (
        rows if len(rows) == len(list(urls)) and all(r == rows[0] and r["viewers"] == viewers for r in rows) else None
    )


def test_every_node_lists_a_session_with_its_viewers_on_every_node(model_path, redis_server):
    """/sessions on the session's node and on another node list the same row (the registry's), and its
    ``viewers`` counts the session's viewers on every node: it counted the owner's only (1 of 3 here, on
    both nodes: the browser viewer on node b said "1 viewer" while it watched with another one there)."""
    nodes = [_node(model_path, redis_server.url, n) for n in ("a", "b")]
    pcm = np.rint(speechlike(20.0, 16000, seed=4) * 32767).astype(np.int16)

    async def main():
        a, b = (n.url for n in nodes)
        async with IngestClient(a, session="x", sample_rate_hz=16000) as ing:
            streaming = asyncio.ensure_future(stream_samples(ing, pcm, realtime=True, block_s=0.02))
            await _until(lambda: _rows_if(b, "x"), what="registry")
            near = ViewerClient(a, session="x", audio=False)
            far = [ViewerClient(b, session="x", audio=False), ViewerClient(b, session="x", kind="blendshapes")]
            for v in (near, *far):
                await v.__aenter__()
            both = await _until(lambda: _same_rows_with((a, b), "x", 3), what="three viewers listed on both nodes")
            for v in far:
                await v.__aexit__(None, None, None)
            after = await _until(lambda: _same_rows_with((a, b), "x", 1), what="the far viewers gone from the rows")
            await near.__aexit__(None, None, None)
            streaming.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await streaming
        return both, after

    both, after = _run_then_stop(nodes, main(), 90)
    assert both[0]["node"] == "a" and both[0]["viewers"] == 3 and after[0]["viewers"] == 1


LONG = "Where were you when the lights went out, and the quick brown fox jumps over the lazy dog? "


async def _messages(viewer: ViewerClient) -> tuple[list[P.Message], list[float]]:
    """Every message a viewer receives until the server closes, in order (frames and audio interleaved),
    and when each arrived (time.perf_counter())."""
    out, at = [], []
    async for m in viewer:
        out.append(m)
        at.append(time.perf_counter())
    return out, at


def test_a_late_text_viewer_on_any_node_gets_the_sentence_so_far(model_path, redis_server):
    """docs/protocol.md section 3 across the cluster: viewers that join a text session mid-sentence at the
    same moment, one on the owner node and one on another node, receive the same messages in the same
    order: the sentence from its first frame (each audio block before its frame), then the live stream
    to the end. (The viewer on the other node used to get only the frames after it joined.)"""
    nodes = [_node(model_path, redis_server.url, n, args=("--text",)) for n in ("a", "b")]

    async def main():
        a, b = (n.url for n in nodes)
        async with connect(ws_url(a, "/text")) as ws:
            await _start_text_session(ws, b, "bot")
            await ws.send(json.dumps({"type": "text", "text": LONG}))
            spoken = json.loads(await ws.recv())
            t_spoken = time.perf_counter()
            await asyncio.sleep(1.0)  # the sentence (several seconds) is playing, ~1.5 s of it released
            va, vb = (ViewerClient(u, session="bot", audio=True) for u in (a, b))
            await asyncio.gather(va.__aenter__(), vb.__aenter__())
            t_joined = time.perf_counter()
            joined_s = t_joined - t_spoken
            got = asyncio.gather(_messages(va), _messages(vb))
            await ws.send(json.dumps({"type": "end"}))
            ended = json.loads(await ws.recv())
            (ma, at_a), (mb, at_b) = await asyncio.wait_for(got, 30)
        health = await _get_json(a, "/health")
        # Reported, not asserted: how long each viewer took to get the sentence so far (the frames up to
        # its media time at the join, which had left the owner by then).
        for node, msgs, at in (("a (owner)", ma, at_a), ("b", mb, at_b)):
            k = max(i for i, m in enumerate(msgs) if m.media_time <= joined_s)
            print(
                f"late text viewer on node {node}: first message {1e3 * (at[0] - t_joined):.1f} ms after the "
                f"join, the {k + 1} messages of the sentence so far {1e3 * (at[k] - t_joined):.1f} ms"
            )
        return spoken, joined_s, ended, (ma, va.close_code), (mb, vb.close_code), health

    spoken, joined_s, ended, (ma, ca), (mb, cb), health = _run_then_stop(nodes, main(), 90)
    assert joined_s < spoken["duration_s"] - 1.0  # they joined while the sentence played
    n = ended["frames"]
    assert [m.index for m in ma if m.kind != P.KIND_AUDIO] == list(range(n))  # from the sentence's first frame
    assert [m.index for m in ma if m.kind == P.KIND_AUDIO] == list(range(n))
    assert ma[0].kind == P.KIND_AUDIO and ma[1].kind == P.KIND_PARAMS  # each audio block before its frame
    assert len(mb) == len(ma)
    for x, y in zip(ma, mb):  # the same messages but for the send-time stamps
        assert (x.kind, x.encoding, x.index, x.media_time, x.scale) == (
            y.kind,
            y.encoding,
            y.index,
            y.media_time,
            y.scale,
        )
        np.testing.assert_array_equal(x.values, y.values)
    assert ca == cb == P.CLOSE_NORMAL
    assert health["replays_answered"] == 1  # b's viewer was answered by the owner


def test_killing_an_edge_node_loses_no_session(model_path, redis_server):
    nodes = {n: _node(model_path, redis_server.url, n) for n in ("a", "b", "c")}
    pcm = np.rint(speechlike(3.0, 16000, seed=6) * 32767).astype(np.int16)

    async def main():
        a, b, c = (nodes[n].url for n in "abc")
        async with IngestClient(a, session="y", sample_rate_hz=16000) as ing:
            await _until(lambda: _get_json(c, "/sessions"), what="registry")
            first = ViewerClient(c, session="y", audio=False)
            await first.__aenter__()
            collect1 = asyncio.ensure_future(first.collect())
            feed = asyncio.ensure_future(stream_samples(ing, pcm, realtime=True, block_s=0.02))
            await asyncio.sleep(1.0)
            nodes["c"].proc.send_signal(signal.SIGKILL)  # the edge node dies under load
            got1 = await asyncio.wait_for(collect1, 10)
            # The viewer reconnects to another node and goes on watching the same session.
            second = ViewerClient(b, session="y", audio=False)
            await second.__aenter__()
            collect2 = asyncio.ensure_future(second.collect())
            await feed
            ended = await ing.end()
            got2 = await asyncio.wait_for(collect2, 20)
            sessions = (await _get_json(a, "/sessions"))["sessions"]
        return got1, got2, ended, sessions

    got1, got2, ended, sessions = _run_then_stop(nodes.values(), main(), 90)
    assert got1.close_code != P.CLOSE_NORMAL and len(got1.frames) > 0  # cut off by the kill
    idx2 = [m.index for m in got2.frames]
    assert idx2 == list(range(idx2[0], ended["frames"]))  # consecutive to the end after reconnecting
    assert idx2[0] <= got1.frames[-1].index + 40  # reconnected within about a second of frames
    assert got2.close_code == P.CLOSE_NORMAL
    assert ended["frames"] == int(np.ceil(len(pcm) / (16000 / 30)))  # the session itself lost nothing
    assert sessions == []


def test_far_viewers_of_a_session_whose_node_dies_are_told_it_is_lost(model_path, redis_server):
    """Issue 15: node a dies (SIGKILL, no end marker) while node b serves a viewer of a's session. Its row
    expires (three missed heartbeats); b must then close that viewer with 1001 "session lost: its node
    stopped" (docs/protocol.md section 5) and drop the feed, instead of leaving it open with no frames and
    no end. b's viewers of its own session and of a session on node c lose nothing. (Before: the viewer
    got nothing more and was never closed.)"""
    nodes = {n: _node(model_path, redis_server.url, n) for n in "abc"}
    pcm = np.rint(speechlike(3.0, 16000, seed=9) * 32767).astype(np.int16)

    async def main():
        a, b, c = (nodes[n].url for n in "abc")
        ingests = {
            name: IngestClient(u, session=name, sample_rate_hz=16000)
            for name, u in (("on-a", a), ("on-b", b), ("on-c", c))
        }
        streams: dict[str, asyncio.Future] = {}
        for ing in ingests.values():
            await ing.__aenter__()
        try:
            await _until(lambda: _rows_if(b, "on-a"), what="registry")
            await _until(lambda: _rows_if(b, "on-c"), what="registry")
            viewers = {name: ViewerClient(b, session=name, audio=False) for name in ingests}
            for v in viewers.values():
                await v.__aenter__()
            for name, owner in (("on-a", a), ("on-c", c)):
                await _until(lambda n=name, o=owner: _published(o, n, {(P.KIND_PARAMS, P.ENC_FLOAT32)}), what="wants")
            got = {name: asyncio.ensure_future(v.collect()) for name, v in viewers.items()}
            for name, ing in ingests.items():
                streams[name] = asyncio.ensure_future(stream_samples(ing, pcm, realtime=True))
            await asyncio.sleep(1.0)
            nodes["a"].proc.send_signal(signal.SIGKILL)
            killed = time.perf_counter()
            lost = await asyncio.wait_for(got["on-a"], 10)  # before the fix: never
            lost_after_s = time.perf_counter() - killed
            health = await _until(lambda: _health_with(b, remote_feeds=1), what="b drops the lost feed")
            await asyncio.gather(streams["on-b"], streams["on-c"])
            ended = {name: await ingests[name].end() for name in ("on-b", "on-c")}
            kept = {name: await asyncio.wait_for(got[name], 20) for name in ("on-b", "on-c")}
        finally:
            for t in streams.values():  # node a's fails once a is gone
                t.cancel()
            await asyncio.gather(*streams.values(), return_exceptions=True)
            for ing in ingests.values():
                with contextlib.suppress(Exception):  # node a's is cut off
                    await ing.__aexit__(None, None, None)
        print(f"cluster: the far viewer of the dead node's session was closed {lost_after_s:.2f} s after the kill")
        return lost, health, ended, kept

    lost, health, ended, kept = _run_then_stop(nodes.values(), main(), 90)
    assert (lost.close_code, lost.close_reason) == (P.CLOSE_GOING_AWAY, "session lost: its node stopped")
    assert len(lost.frames) > 0  # it was watching when a died
    assert health["remote_feeds"] == 1  # the feed of c's session only
    for name in ("on-b", "on-c"):  # untouched: every frame, then the session's own end
        assert [m.index for m in kept[name].frames] == list(range(ended[name]["frames"]))
        assert kept[name].close_code == P.CLOSE_NORMAL


async def _health_with(url: str, **fields) -> dict | None:
    h = await _get_json(url, "/health")
    return h if all(h.get(k) == v for k, v in fields.items()) else None


def test_redis_going_away_shows_on_health_and_nodes_recover(model_path, redis_server):
    nodes = [_node(model_path, redis_server.url, n) for n in ("a", "b")]
    pcm = np.rint(speechlike(4.0, 16000, seed=8) * 32767).astype(np.int16)

    async def main():
        a, b = (n.url for n in nodes)
        async with IngestClient(a, session="z", sample_rate_hz=16000) as ing:
            async with ViewerClient(a, session="z", audio=False) as local:
                # A far viewer watching through the outage: the restarted Redis holds no row of "z" until a
                # re-registers it, which must not read as a's death (1001 "session lost").
                await _until(lambda: _rows_if(b, "z"), what="registry")
                far = ViewerClient(b, session="z", audio=False)
                await far.__aenter__()
                await _until(lambda: _published(a, "z", {(P.KIND_PARAMS, P.ENC_FLOAT32)}), what="wants")
                collect_far = asyncio.ensure_future(far.collect())
                collect = asyncio.ensure_future(local.collect())
                feed = asyncio.ensure_future(stream_samples(ing, pcm, realtime=True, block_s=0.02))
                await asyncio.sleep(0.5)
                redis_server.stop()
                down = await _until(lambda: _health_if(a, "degraded"), what="degraded health")
                await asyncio.sleep(0.5)
                redis_server.start()
                up = [await _until(lambda u=u: _health_if(u, "ok"), 15, what="recovery") for u in (a, b)]
                # Re-registered: node b sees the session again and can serve a viewer of it.
                rows = await _until(lambda: _rows_if(b, "z"), 10, what="re-registration")
                remote = ViewerClient(b, session="z", audio=False)
                await remote.__aenter__()
                collect_remote = asyncio.ensure_future(remote.collect())
                await feed
                ended = await ing.end()
                got = await asyncio.wait_for(collect, 20)
                got_remote = await asyncio.wait_for(collect_remote, 20)
                got_far = await asyncio.wait_for(collect_far, 20)
        return down, up, rows, ended, got, got_remote, got_far

    down, up, rows, ended, got, got_remote, got_far = _run_then_stop(nodes, main(), 90)
    assert down["status"] == "degraded" and down["redis"].startswith("down")
    assert all(h["redis"] == "ok" for h in up) and rows[0]["node"] == "a"
    assert [m.index for m in got.frames] == list(range(ended["frames"]))  # the local viewer lost nothing
    assert got_remote.close_code == P.CLOSE_NORMAL and len(got_remote.frames) > 0
    assert (got_far.close_code, got_far.close_reason) == (P.CLOSE_NORMAL, "session ended")
    assert got_far.frames[-1].index == ended["frames"] - 1  # it went on to the end after the outage


def test_a_name_opened_on_two_nodes_while_redis_was_away_has_one_owner_after(model_path, redis_server):
    """Redis restarted under a running cluster: session "dup" streams on node a, watched from node c; while Redis is
    away an ingest opens "dup" on node b too (a claim cannot be checked then: it opens locally). Both nodes used to
    rewrite the row every heartbeat once Redis was back and both published on the one channel: c's viewer got the two
    sessions' frames interleaved (indices going backwards 20 times in 87 frames), then 1001 "session lost: its node
    stopped". Now the first to re-register keeps the name, the other's session goes on for its own ingest only."""
    nodes = [_node(model_path, redis_server.url, n) for n in ("a", "b", "c")]
    pcm_a = np.rint(speechlike(5.0, 16000, seed=9) * 32767).astype(np.int16)
    pcm_b = np.rint(speechlike(3.0, 16000, seed=10) * 32767).astype(np.int16)

    async def main():
        a, b, c = (n.url for n in nodes)
        async with IngestClient(a, session="dup", sample_rate_hz=16000) as ing_a:
            await _until(lambda: _rows_if(c, "dup"), what="registry")
            async with ViewerClient(c, session="dup", audio=False) as far:
                await _until(lambda: _published(a, "dup", {(P.KIND_PARAMS, P.ENC_FLOAT32)}), what="wants")
                collect = asyncio.ensure_future(far.collect())
                feed_a = asyncio.ensure_future(stream_samples(ing_a, pcm_a, realtime=True, block_s=0.02))
                await asyncio.sleep(0.5)
                redis_server.stop()
                await _until(lambda: _health_if(b, "degraded"), what="degraded health")
                async with IngestClient(b, session="dup", sample_rate_hz=16000) as ing_b:  # opens locally
                    feed_b = asyncio.ensure_future(stream_samples(ing_b, pcm_b, realtime=True, block_s=0.02))
                    await asyncio.sleep(0.3)
                    redis_server.start()
                    for u in (a, b, c):
                        await _until(lambda u=u: _health_if(u, "ok"), 15, what="recovery")
                    await asyncio.sleep(1.0)  # five heartbeats with both sessions live
                    owners = [[r["node"] for r in (await _get_json(u, "/sessions"))["sessions"]] for u in (a, b, c)]
                    yielded = [(await _get_json(u, "/health"))["names_yielded"] for u in (a, b)]
                    await feed_b
                    ended_b = await ing_b.end()
                await feed_a
                ended_a = await ing_a.end()
                got = await asyncio.wait_for(collect, 20)
        return owners, yielded, ended_a, ended_b, got

    owners, yielded, ended_a, ended_b, got = _run_then_stop(nodes, main(), 90)
    assert ended_a["frames"] == 150 and ended_b["frames"] == 90  # both ingests were served whole
    idx = [m.index for m in got.frames]
    assert idx == sorted(set(idx)) and idx, idx  # one session's frames, never the other's between them
    assert owners[0] == owners[1] == owners[2] and len(owners[0]) == 1, owners  # one row, the same on every node
    assert sorted(yielded) == [0, 1], yielded  # the other node's session yielded the name
    if owners[0] == ["a"]:  # a kept the name: c's viewer went on to a's end
        assert idx[-1] == ended_a["frames"] - 1 and got.close_code == P.CLOSE_NORMAL
    else:  # b took it first: c's viewer of a's session is told it is lost
        assert (got.close_code, got.close_reason) == (P.CLOSE_GOING_AWAY, "session lost: its node stopped")


async def _health_if(url: str, status: str) -> dict | None:
    h = await _get_json(url, "/health")
    return h if h["status"] == status else None


async def _rows_if(url: str, name: str) -> list | None:
    rows = (await _get_json(url, "/sessions"))["sessions"]
    return rows if any(r["name"] == name for r in rows) and rows[0].get("node") else None


def test_an_ingest_landing_on_an_edge_node_is_forwarded(model_path, redis_server):
    nodes = [_node(model_path, redis_server.url, "a"), _node(model_path, redis_server.url, "e", role="edge")]
    pcm = np.rint(speechlike(1.0, 16000, seed=2) * 32767).astype(np.int16)

    async def main():
        a, e = (n.url for n in nodes)
        await _until(lambda: _get_json(e, "/health"), what="health")
        await asyncio.sleep(0.5)  # both nodes have announced themselves
        async with IngestClient(e, session="fw", sample_rate_hz=16000) as ing:
            rows = (await _get_json(a, "/sessions"))["sessions"]
            async with ViewerClient(e, session="fw", audio=False) as view:
                await _until(lambda: _published(a, "fw", {(P.KIND_PARAMS, P.ENC_FLOAT32)}), what="wants")
                collect = asyncio.ensure_future(view.collect())
                await stream_samples(ing, pcm, realtime=False)
                ended = await ing.end()
                got = await asyncio.wait_for(collect, 20)
        return rows, ended, got

    rows, ended, got = _run_then_stop(nodes, main(), 60)
    assert [(r["name"], r["node"]) for r in rows] == [("fw", "a")]  # computed on a, not on the edge
    assert ended["type"] == "ended" and [m.index for m in got.frames] == list(range(ended["frames"]))
    assert got.close_code == P.CLOSE_NORMAL


def test_a_wrong_redis_address_is_one_line_at_start(model_path):
    facecast = str(Path(sys.executable).parent / "facecast")
    cfg = Path(model_path).parent / "bad_redis.toml"
    cfg.write_text(f'[server]\nredis_url = "redis://127.0.0.1:{_free_port()}/0"\n')
    out = subprocess.run(
        [facecast, "serve", "--port", "0", "--no-head", "--model", str(model_path), "--config", str(cfg)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode != 0
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "cannot reach Redis at redis://127.0.0.1:" in lines[0], out.stderr


@pytest.mark.parametrize("replay", [True, False], ids=["text", "audio"])
def test_a_far_viewer_joining_as_the_session_ends_gets_its_end(model_path, redis_server, replay):
    """Issue 15: a session on node a ends while a viewer on node b joins. The owner publishes the end
    marker, then drops its row; a viewer whose node looked the row up before the drop but subscribed
    after the marker hears no marker. It must still get the session's end (its close code, docs/protocol.md
    section 4) instead of waiting forever, and its node must keep nothing of the session (feed,
    subscription). The owner's release is replayed here step by step on the real Redis (row of a real
    text session of node a, end record, marker, row not yet dropped), since the real one passes that
    point within a millisecond; for a text session b first asks node a for the sentence (answered
    empty: a has no such session)."""
    import redis.asyncio as aioredis

    nodes = [_node(model_path, redis_server.url, n, args=("--text",)) for n in ("a", "b")]

    async def main():
        a, b = (n.url for n in nodes)
        r = aioredis.Redis.from_url(redis_server.url)
        try:
            async with connect(ws_url(a, "/text")) as ws:
                await _start_text_session(ws, b, "bot")
                row = json.loads(await r.get("facecast:session:bot"))
                row.update({"name": "gone", "replay": replay})
                end = json.dumps({"code": P.CLOSE_GOING_AWAY, "reason": "server shutting down"})
                # node a's Cluster.release, up to the moment before it drops the row
                await r.set("facecast:session:gone", json.dumps(row), px=5000)
                await r.set("facecast:ended:gone", end, px=10_000)
                assert await r.publish("facecast:frames:gone", b"\x00END" + end.encode()) == 0  # no one heard it
                viewer = ViewerClient(b, session="gone", audio=True)
                await asyncio.wait_for(viewer.__aenter__(), 10)
                got = await asyncio.wait_for(viewer.collect(), 10)  # before the fix: no end, ever
                await _until(lambda: _no_feed(b, r, "gone"), what="node b drops the feed and its subscription")
                # the real session on a goes on, and its own end leaves an end record like the one above
                await ws.send(json.dumps({"type": "end"}))
                assert json.loads(await ws.recv())["type"] == "ended"
                record = await _until(lambda: r.get("facecast:ended:bot"), what="end record")
                # written before the marker; the row goes after it
                await _until(lambda: _gone(r, "facecast:session:bot"), what="the row dropped")
            return got, json.loads(record)
        finally:
            await r.aclose()

    got, record = _run_then_stop(nodes, main(), 90)
    assert (got.close_code, got.close_reason) == (P.CLOSE_GOING_AWAY, "server shutting down")
    assert got.frames == [] and got.audio == []
    assert record == {"code": P.CLOSE_NORMAL, "reason": record["reason"]}


async def _start_text_session(ws, far: str, name: str) -> None:
    """Start text session ``name`` on the connection ``ws`` and wait until the node at ``far`` lists it."""
    await ws.send(json.dumps({"type": "start", "session": name, "language": "en"}))
    assert json.loads(await ws.recv())["type"] == "started"
    await _until(lambda: _rows_if(far, name), what="registry")


async def _gone(r, key: str) -> bool:
    return await r.exists(key) == 0


def test_far_viewers_joining_around_a_real_session_end_all_get_an_end(model_path, redis_server):
    """The same race with the real owner: viewers on node b join a text session of node a every 10 ms
    while its last sentence plays and it ends. Each one, whenever it lands (before the end, during the owner's replay
    answer, between the marker and the row's drop, after), gets a close code within 10 s: the session's
    (1000) or "no such session" (4004, it had gone); none hangs, and node b keeps no feed."""
    import redis.asyncio as aioredis

    nodes = [_node(model_path, redis_server.url, n, args=("--text",)) for n in ("a", "b")]

    async def join(b: str) -> int | None:
        viewer = ViewerClient(b, session="bot", audio=True)
        try:
            await asyncio.wait_for(viewer.__aenter__(), 10)
        except ServerClosed as exc:
            return exc.code
        return (await asyncio.wait_for(viewer.collect(), 10)).close_code

    async def main():
        a, b = (n.url for n in nodes)
        r = aioredis.Redis.from_url(redis_server.url)
        try:
            async with connect(ws_url(a, "/text")) as ws:
                await _start_text_session(ws, b, "bot")
                await ws.send(json.dumps({"type": "text", "text": "Bob bought a map."}))
                assert json.loads(await ws.recv())["type"] == "spoken"
                await ws.send(json.dumps({"type": "end"}))  # it ends once the sentence has played
                joins, after = [], 0
                while after < 5 and len(joins) < 400:  # until five joins after the row is gone
                    joins.append(asyncio.ensure_future(join(b)))
                    await asyncio.sleep(0.01)
                    after += await r.exists("facecast:session:bot") == 0
                codes = await asyncio.gather(*joins)
                await _until(lambda: _no_feed(b, r, "bot"), what="node b drops the feed and its subscription")
            return codes
        finally:
            await r.aclose()

    codes = _run_then_stop(nodes, main(), 90)
    assert set(codes) <= {P.CLOSE_NORMAL, P.CLOSE_NOT_FOUND}, codes
    assert P.CLOSE_NORMAL in codes and P.CLOSE_NOT_FOUND in codes  # some joined before the end, some after


async def _no_feed(url: str, r, name: str) -> bool:
    """Node ``url`` holds no feed and Redis no subscription of session ``name``."""
    health = await _get_json(url, "/health")
    subscribers = dict(await r.pubsub_numsub(f"facecast:frames:{name}"))
    return health["remote_feeds"] == 0 and all(n == 0 for n in subscribers.values())


def test_a_healthy_redis_never_reads_as_down_at_start(redis_server, caplog):
    """The first heartbeat used to run while the subscription connection was still being opened and
    took its missing connection for a lost one: every node logged "Redis unreachable ... subscription
    lost" at start and /health read degraded for half a second, with redis-server up all along."""
    from server.cluster import Cluster

    async def main() -> list[bool]:
        async def end_feed(feed) -> None:
            return None

        cluster = Cluster(
            redis_server.url,
            node="a",
            advertise="http://127.0.0.1:1",
            heartbeat_s=0.2,
            deliver=lambda *a: None,
            end_feed=end_feed,
        )
        await cluster.start()
        seen = []
        try:
            deadline = time.monotonic() + 1.5  # seven heartbeats
            while time.monotonic() < deadline:
                seen.append(cluster.up)
                await asyncio.sleep(0.005)
        finally:
            await cluster.stop()
        return seen

    with caplog.at_level("WARNING", logger="facecast.cluster"):
        seen = asyncio.run(asyncio.wait_for(main(), 30))
    assert all(seen), f"read as down in {seen.count(False)} of {len(seen)} polls"
    assert not [r for r in caplog.records if "unreachable" in r.getMessage()]


@pytest.mark.parametrize(
    ("url", "shown"),
    [
        ("redis://:hunter2@127.0.0.1:{port}/0", "redis://:***@127.0.0.1:{port}/0"),
        ("rediss://default:hunter2@127.0.0.1:{port}/0", "rediss://default:***@127.0.0.1:{port}/0"),
        ("redis://127.0.0.1:{port}/0?password=hunter2&db=0", "redis://127.0.0.1:{port}/0?password=***&db=0"),
    ],
)
def test_a_redis_password_in_the_url_is_never_shown(url, shown):
    """docs/deploy.md keeps a Redis password in the config file's URL; a node that could not reach Redis
    printed the whole URL, password included ("cannot reach Redis at redis://:hunter2@..."), as did the
    start-up line and the logs of Redis going away and coming back, which all show ``shown_url``."""
    from server.cluster import Cluster, shown_url
    from server.errors import ServerError

    port = _free_port()  # nothing listens there: the connection is refused at once
    url, shown = url.format(port=port), shown.format(port=port)
    assert shown_url(url) == shown
    assert shown_url(f"redis://127.0.0.1:{port}/0") == f"redis://127.0.0.1:{port}/0"  # nothing to hide

    async def end_feed(feed) -> None:
        return None

    cluster = Cluster(
        url, node="a", advertise="http://127.0.0.1:1", heartbeat_s=0.2, deliver=lambda *a: None, end_feed=end_feed
    )
    with pytest.raises(ServerError) as refused:
        asyncio.run(asyncio.wait_for(cluster.start(), 10))
    assert "hunter2" not in str(refused.value)
    assert str(refused.value).startswith(f"cannot reach Redis at {shown}: ")
