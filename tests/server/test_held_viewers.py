"""Viewers held for a session that has not started (the view query's ``wait``, docs/protocol.md section 3): a real
server and real WebSocket clients over loopback, no mocks."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest
from websockets.asyncio.client import connect

from clients.client import IngestClient, ServerClosed, ViewerClient, stream_samples, ws_url
from realtime_core.pipeline import speech_to_params
from tests.live_server import running
from tests.speech import speechlike
from wire import protocol as P

pytestmark = pytest.mark.system


async def _until(predicate, what: str, timeout_s: float = 10.0) -> None:
    end = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.005)


async def _refusal(viewer: ViewerClient) -> tuple[int | None, str, float]:
    """Connect a viewer that must be refused: (close code, reason, seconds until the refusal)."""
    t0 = time.monotonic()
    try:
        async with viewer:
            pass
    except ServerClosed as exc:
        return exc.code, exc.reason, time.monotonic() - t0
    raise AssertionError("the viewer was not refused")


def _pcm(seconds: float, seed: int) -> np.ndarray:
    x = speechlike(seconds, 16000, seed=seed)
    return np.clip(np.rint(x.astype(np.float64) * 32768), -32768, 32767).astype(np.int16)


@pytest.mark.parametrize("source", ["ingest", "local"])
def test_a_viewer_held_before_its_session_gets_every_audio_block_and_frame(model, source):
    """A viewer that connects before its session exists and asks to wait is subscribed while the session opens, so
    it gets all the audio ingested (sample for sample) and every frame from 0, even when the first block is fed at
    once: over /ingest sent without pause right after "started"; from a local source (facecast serve --mic/--file)
    fed in the same task right after the session opened. A viewer that retried after a 4004 joined after the
    session's first push and lost its first block(s) (0-630 samples in stop 46's runs)."""
    pcm = _pcm(1.0, seed=2)
    x = pcm.astype(np.float32) / 32768
    ref = speech_to_params(model, x).astype(np.float32)

    async def local_blocks():
        for i in range(0, len(x), 320):
            yield x[i : i + 320]

    async def main():
        async with running(model) as srv:
            server = srv
            viewers = [ViewerClient(srv.url, session="held", kind="params", wait_s=20) for _ in range(2)]
            collected = [asyncio.ensure_future(_collect(v)) for v in viewers]
            await _until(lambda: len(server.holds) == 2, "two held viewers")
            assert server.n_viewers == 2 and server.metrics()["viewers_held"] == 2
            if source == "ingest":
                async with IngestClient(srv.url, session="held", sample_rate_hz=16000) as ing:
                    await stream_samples(ing, pcm, realtime=False, block_s=0.02)
                    ended = await ing.end()
            else:
                live = await server.run_source("held", local_blocks(), sample_rate_hz=16000)
                ended = {"frames": live.session.frames_out}
            got = await asyncio.gather(*collected)
            await _until(lambda: server.n_viewers == 0 and not server.holds, "the viewers gone")
            return ended, got

    ended, got = asyncio.run(asyncio.wait_for(main(), 60))
    assert ended["frames"] == len(ref)
    for rec in got:
        assert [m.index for m in rec.frames] == list(range(len(ref))), (rec.close_code, rec.close_reason)
        np.testing.assert_array_equal(rec.values(), ref)
        audio = rec.audio_samples()
        assert len(audio) == len(pcm)  # every block, the first included
        np.testing.assert_allclose(audio, x, atol=0.5 / 32768)
        assert rec.audio[0].index == 0 and rec.audio[0].media_time == 0.0
        assert rec.close_code == P.CLOSE_NORMAL


async def _collect(viewer: ViewerClient):
    async with viewer:
        return await viewer.collect()


def test_a_wait_that_runs_out_is_4004_saying_how_long_and_no_wait_is_4004_at_once(model):
    """Held for a session that never starts: 4004 after the wait, saying how long it waited (cut to the server's
    max_view_wait_s). Without ``wait`` (or 0), 4004 at once as before; a ``wait`` that is not a number of seconds
    >= 0 is 4400."""

    async def main():
        async with running(model, max_view_wait_s=0.5) as srv:
            out = {
                "held": await _refusal(ViewerClient(srv.url, session="nobody", wait_s=0.3)),
                "capped": await _refusal(ViewerClient(srv.url, session="nobody", wait_s=30)),
                "none": await _refusal(ViewerClient(srv.url, session="nobody")),
            }
            for bad in ("abc", "-1", "nan", "inf"):
                async with connect(ws_url(srv.url, f"/view?session=nobody&wait={bad}")) as ws:
                    await ws.wait_closed()
                    out[bad] = (ws.close_code, ws.close_reason, 0.0)
            return out, srv.n_viewers, len(srv.holds)

    out, n_viewers, held = asyncio.run(asyncio.wait_for(main(), 30))
    code, reason, took = out["held"]
    assert (code, reason) == (P.CLOSE_NOT_FOUND, "no session 'nobody' (waited 0.3 s for it to start)")
    assert took >= 0.3
    code, reason, took = out["capped"]
    assert (code, reason) == (P.CLOSE_NOT_FOUND, "no session 'nobody' (waited 0.5 s for it to start)")
    assert 0.5 <= took < 30
    code, reason, took = out["none"]
    assert (code, reason) == (P.CLOSE_NOT_FOUND, "no session 'nobody'")
    for bad in ("abc", "-1", "nan", "inf"):
        code, reason, _ = out[bad]
        assert code == P.CLOSE_BAD_REQUEST and reason.startswith("wait must be a number of seconds >= 0"), reason
    assert n_viewers == 0 and held == 0


def test_a_held_viewer_that_leaves_is_dropped_and_others_are_served(model):
    """A held viewer that hangs up while held is forgotten (no hold, n_viewers back to 0); held viewers count
    towards max_viewers; the token is checked before anyone is held; a server stopping closes its held viewers
    with 1001."""
    pcm = _pcm(0.5, seed=4)

    async def main():
        async with running(model, max_viewers=2, token="sesame") as srv:
            server = srv
            out = {"untokened": await _refusal(ViewerClient(srv.url, session="s", wait_s=20))}
            assert not server.holds
            url = ws_url(srv.url, "/view?session=s&wait=20&token=sesame")
            async with connect(url):
                await _until(lambda: len(server.holds) == 1, "the viewer held")
            await _until(lambda: not server.holds and server.n_viewers == 0, "the viewer that left dropped")
            stays = asyncio.ensure_future(_collect(ViewerClient(srv.url, session="s", wait_s=20, token="sesame")))
            async with connect(url):
                await _until(lambda: len(server.holds) == 2, "two held")
                out["full"] = await _refusal(ViewerClient(srv.url, session="s", wait_s=20, token="sesame"))
            await _until(lambda: len(server.holds) == 1 and server.n_viewers == 1, "one left")
            async with IngestClient(srv.url, session="s", sample_rate_hz=16000, token="sesame") as ing:
                await stream_samples(ing, pcm, realtime=False, block_s=0.02)
                ended = await ing.end()
            out["stays"] = await stays
            out["ended"] = ended
            stopping = asyncio.ensure_future(_refusal(ViewerClient(srv.url, session="t", wait_s=20, token="sesame")))
            await _until(lambda: len(server.holds) == 1, "held at the stop")
        out["stopped"] = await stopping
        return out

    out = asyncio.run(asyncio.wait_for(main(), 60))
    assert out["untokened"][:2] == (P.CLOSE_UNAUTHORIZED, "missing or wrong token")
    assert out["full"][:2] == (P.CLOSE_TRY_LATER, "server is full (2 viewers)")
    rec = out["stays"]
    assert [m.index for m in rec.frames] == list(range(out["ended"]["frames"]))
    assert len(rec.audio_samples()) == len(pcm)
    assert out["stopped"][:2] == (P.CLOSE_GOING_AWAY, "server shutting down")
