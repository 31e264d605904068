"""The service over loopback: a real server, real WebSocket clients, no mocks.

Each test runs its own server on a free port inside ``asyncio.run``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket

import numpy as np
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from assets.audio import read_audio
from clients.client import IngestClient, ServerClosed, ViewerClient, http_get, stream_samples, ws_url
from realtime_core.blendshapes import ARKIT_NAMES, blendshape_weights
from realtime_core.features.resample import resample_audio
from realtime_core.pipeline import speech_to_params
from server.app import FacecastServer
from server.config import ServerConfig
from server.eventloop import process_loop
from server.eventloop import run as run_on_loop
from tests.live_server import running
from tests.speech import speechlike
from wire import protocol as P

# A real server and clients over loopback sockets.
pytestmark = pytest.mark.system


def _int16(samples: np.ndarray) -> np.ndarray:
    """read_audio's float32 (int16 / 32768) back to the file's int16 samples, exactly."""
    return np.clip(np.rint(samples.astype(np.float64) * 32768), -32768, 32767).astype(np.int16)


async def _watch_then_stream(url, name, samples_i16, rate, *, kinds, realtime=False, token=None):
    """Start a session, attach viewers of the given (kind, encoding) pairs, stream, end; results."""
    async with IngestClient(url, session=name, sample_rate_hz=rate, token=token) as ing:
        viewers = [ViewerClient(url, session=name, kind=k, encoding=e, token=token) for k, e in kinds]
        for v in viewers:
            await v.__aenter__()
        tasks = [asyncio.ensure_future(v.collect()) for v in viewers]
        await stream_samples(ing, samples_i16, realtime=realtime, block_s=0.02)
        ended = await ing.end()
        results = await asyncio.gather(*tasks)
        for v in viewers:
            await v.__aexit__(None, None, None)
    return ended, results


@pytest.mark.parametrize("which", ["wav16k", "wav48k"])
def test_wav_ingest_gives_animate_params_frame_for_frame(which, model, request):
    path = request.getfixturevalue(which)
    samples, rate = read_audio(path)
    # What `facecast animate` computes for this file.
    ref = speech_to_params(model, resample_audio(samples, rate, model.sample_rate_hz))
    pcm = _int16(samples)

    async def main():
        async with running(model) as srv:
            return await _watch_then_stream(srv.url, "wav", pcm, rate, kinds=[("params", None)])

    ended, (got,) = asyncio.run(main())
    n = len(ref)
    assert ended["frames"] == n
    assert n == int(np.ceil(len(resample_audio(samples, rate, 16000)) / (16000 / 30)))  # one frame per 33.3 ms
    assert [m.index for m in got.frames] == list(range(n))
    times = np.array([m.media_time for m in got.frames])
    assert np.all(np.diff(times) > 0)
    np.testing.assert_allclose(times, np.arange(n) / 30, atol=1e-12)
    assert got.close_code == P.CLOSE_NORMAL
    if rate == model.sample_rate_hz:
        np.testing.assert_array_equal(got.values(), ref.astype(np.float32))
        # The relayed audio is the session's audio, with media times of its first samples.
        np.testing.assert_allclose(got.audio_samples(), pcm / 32768.0, atol=0.5 / 32768)
    else:
        np.testing.assert_allclose(got.values(), ref.astype(np.float32), rtol=1e-3, atol=1e-3)
    starts = np.cumsum([0] + [m.values.size for m in got.audio])[:-1]
    np.testing.assert_allclose([m.media_time for m in got.audio], starts / 16000)


def test_every_viewer_kind_decodes_to_the_same_motion(model, head, wav16k):
    samples, rate = read_audio(wav16k)
    pcm = _int16(samples)[:rate]  # 1 s is enough
    kinds = [
        ("params", None),
        ("deltas", "int16"),
        ("deltas", "float16"),
        ("blendshapes", "arkit52"),
        ("blendshapes", "ovr15"),
    ]

    async def main():
        async with running(model, head) as srv:
            out = await _watch_then_stream(srv.url, "kinds", pcm, rate, kinds=kinds)
            mesh_status, glb = await http_get(srv.url, "/head/mesh")
            return out, mesh_status, glb

    (ended, results), mesh_status, glb = asyncio.run(main())
    params, d16, dh, ark, ovr = results
    p = params.values()
    assert len(p) == ended["frames"] == len(d16.frames) == len(dh.frames) == len(ark.frames) == len(ovr.frames)
    desc = d16.description
    moving = np.array(desc["head"]["moving_vertices"])
    np.testing.assert_array_equal(moving, head.rig.moving)
    assert desc["values_per_frame"] == 3 * len(moving) and desc["head"]["vertex_count"] == len(head.mesh.vertices)
    for k in (0, len(p) // 2, len(p) - 1):
        want = head.rig.displacements(p[k]).reshape(-1)
        peak = np.abs(want).max()
        np.testing.assert_allclose(d16.frames[k].values, want, atol=peak / 32767 + 1e-6 * peak)
        np.testing.assert_allclose(dh.frames[k].values, want, atol=peak * 1e-3)
    assert ark.description["names"] == list(ARKIT_NAMES)
    np.testing.assert_allclose(ark.values(), blendshape_weights(p, "arkit52"), atol=1e-5)  # p is float32
    np.testing.assert_allclose(ovr.values(), blendshape_weights(p, "ovr15"), atol=1e-5)
    assert mesh_status == 200 and glb[:4] == b"glTF"


async def _expect_close(coro_factory) -> tuple[int | None, str]:
    """Run a misbehaving client; return the close code and reason the server sent it."""
    try:
        await coro_factory()
    except ServerClosed as exc:
        return exc.code, exc.reason
    except ConnectionClosed as exc:
        return (exc.rcvd.code, exc.rcvd.reason) if exc.rcvd else (None, "")
    except InvalidStatus as exc:  # refused before the handshake: an HTTP status, not a close code
        return exc.response.status_code, exc.response.body.decode()
    return None, "not closed"


async def _raw(url: str, path: str, *messages, max_size=None):
    """Connect, send messages in order, then wait for the server to close us."""
    async with connect(ws_url(url, path), compression=None, max_size=max_size) as ws:
        for m in messages:
            await ws.send(m)
            await asyncio.sleep(0.01)
        while True:
            await asyncio.wait_for(ws.recv(), 10)


def _start(**kw) -> str:
    msg = {"type": "start", "session": "bad", "sample_rate": 16000, "format": "pcm_s16le", "token": "sesame"}
    msg.update(kw)
    return json.dumps({k: v for k, v in msg.items() if v is not None})


def test_bad_clients_get_close_codes_and_a_healthy_session_loses_nothing(model):
    x = speechlike(2.0, 16000, seed=5)
    pcm = _int16(x)
    ref = speech_to_params(model, pcm.astype(np.float32) / 32768)
    cases = [
        (
            "garbage first",
            lambda u: _raw(u, "/ingest", b"\x00\xffgarbage"),
            P.CLOSE_UNSUPPORTED_DATA,
            "expected a JSON start",
        ),
        ("not json", lambda u: _raw(u, "/ingest", "{garbage"), P.CLOSE_INVALID_PAYLOAD, "not valid JSON"),
        ("no rate", lambda u: _raw(u, "/ingest", _start(sample_rate=None)), P.CLOSE_BAD_REQUEST, "lacks sample_rate"),
        (
            "absurd rate",
            lambda u: _raw(u, "/ingest", _start(sample_rate=10**9)),
            P.CLOSE_BAD_REQUEST,
            "sample_rate must be",
        ),
        (
            "garbage audio",
            lambda u: _raw(u, "/ingest", _start(session="g1"), b"\x01\x02\x03"),
            P.CLOSE_INVALID_PAYLOAD,
            "not a whole number",
        ),
        (
            "text for binary",
            lambda u: _raw(u, "/ingest", _start(session="g2"), "hello"),
            P.CLOSE_UNSUPPORTED_DATA,
            "audio must be sent as binary",
        ),
        (
            "second start",
            lambda u: _raw(u, "/ingest", _start(session="g3"), _start(session="g3")),
            P.CLOSE_POLICY,
            "second start",
        ),
        (
            "unknown type",
            lambda u: _raw(u, "/ingest", _start(session="g4"), json.dumps({"type": "dance"})),
            P.CLOSE_POLICY,
            "unknown message type",
        ),
        ("oversized", lambda u: _raw(u, "/ingest", _start(session="g5"), b"\x00" * 70000), P.CLOSE_TOO_BIG, ""),
        (
            "wrong token",
            lambda u: _raw(u, "/ingest", _start(session="g6", token="nope")),
            P.CLOSE_UNAUTHORIZED,
            "token",
        ),
        ("taken name", lambda u: _raw(u, "/ingest", _start(session="healthy")), P.CLOSE_CONFLICT, "already exists"),
        (
            "unknown session",
            lambda u: ViewerClient(u, session="nosuch", token="sesame").__aenter__(),
            P.CLOSE_NOT_FOUND,
            "no session",
        ),
        (
            "viewer bad token",
            lambda u: ViewerClient(u, session="healthy", token="nope").__aenter__(),
            P.CLOSE_UNAUTHORIZED,
            "token",
        ),
        (
            "viewer bad kind",
            lambda u: ViewerClient(u, session="healthy", kind="smell", token="sesame").__aenter__(),
            P.CLOSE_BAD_REQUEST,
            "kind must be",
        ),
        (
            "viewer talks",
            lambda u: _raw(u, "/view?session=healthy&token=sesame", "hi"),
            P.CLOSE_POLICY,
            "viewers send only expression controls",
        ),
        ("no endpoint", lambda u: _raw(u, "/elsewhere"), 404, "no WebSocket endpoint"),  # HTTP 404
    ]

    async def main():
        async with running(model, token="sesame", max_message_bytes=65536) as srv:
            url = srv.url
            async with IngestClient(url, session="healthy", sample_rate_hz=16000, token="sesame") as ing:
                async with ViewerClient(url, session="healthy", token="sesame") as view:
                    collect = asyncio.ensure_future(view.collect())
                    feed = asyncio.ensure_future(stream_samples(ing, pcm, realtime=True, block_s=0.02))
                    outcomes = []
                    for _name, factory, _, _ in cases:
                        outcomes.append(await asyncio.wait_for(_expect_close(lambda f=factory: f(url)), 15))
                    await feed
                    ended = await ing.end()
                    got = await collect
            status, body = await http_get(url, "/health")
            return outcomes, ended, got, status, json.loads(body)

    outcomes, ended, got, status, health = asyncio.run(main())
    for (name, _, code, reason), (got_code, got_reason) in zip(cases, outcomes):
        assert got_code == code, f"{name}: closed with {got_code} {got_reason!r}, expected {code}"
        assert reason in got_reason, f"{name}: reason {got_reason!r} lacks {reason!r}"
    assert status == 200 and health["status"] == "ok"
    assert ended["frames"] == len(ref)
    assert [m.index for m in got.frames] == list(range(len(ref)))  # the healthy session lost no frame
    np.testing.assert_array_equal(got.values(), ref.astype(np.float32))


def test_controls_are_applied_or_rejected_with_a_reason(model):
    pcm = _int16(speechlike(0.6, 16000))

    async def main():
        async with running(model) as srv, IngestClient(srv.url, session="c", sample_rate_hz=16000) as ing:
            async with ViewerClient(srv.url, session="c", audio=False) as view:
                collect = asyncio.ensure_future(view.collect())
                ok = await ing.control(gain={"mouth_open": 0.0})
                bad = await ing.control(eyebrows=1)
                await stream_samples(ing, pcm, realtime=False)
                await ing.end()
                return ok, bad, await collect

    ok, bad, got = asyncio.run(main())
    assert ok["type"] == "ack" and ok["controls"]["gain"]["mouth_open"] == 0.0
    assert bad["type"] == "rejected" and "unknown control 'eyebrows'" in bad["reason"]
    assert len(got.frames) > 0 and np.all(got.values()[:, 2] == 0.0) and np.any(got.values()[:, 0] != 0.0)
    assert got.audio == []  # audio=0: no audio messages


@pytest.mark.parametrize("workers", [0, 1])
def test_expression_controls_from_ingest_and_from_a_viewer(model, workers):
    """The browser picker's route: a viewer's expression control is applied (ack) or rejected with a
    reason while the session streams on; the ingest client's control does the same (in the server's
    process and in a compute worker)."""
    from websockets.asyncio.client import connect

    pcm = _int16(speechlike(1.5, 16000, seed=3))

    async def main():
        async with running(model, workers=workers) as srv:
            async with IngestClient(srv.url, session="e", sample_rate_hz=16000) as ing:
                async with ViewerClient(srv.url, session="e", audio=False) as view:
                    collect = asyncio.ensure_future(view.collect())
                    bad_ingest = await ing.control(expression={"name": "smile", "intensity": 3})
                    async with connect(srv.url.replace("http", "ws") + "/view?session=e&audio=0") as raw:
                        desc = json.loads(await raw.recv())
                        replies = []
                        for msg in (
                            {"type": "control", "expression": {"name": "joy"}},
                            {"type": "control", "expression": {"name": "smile", "intensity": 1.0, "at": 0.0}},
                        ):
                            await raw.send(json.dumps(msg))
                            while True:  # skip binary frames until the text reply
                                m = await asyncio.wait_for(raw.recv(), 10)
                                if isinstance(m, str):
                                    replies.append(json.loads(m))
                                    break
                        await stream_samples(ing, pcm, realtime=False)
                        await ing.end()
                    return bad_ingest, desc, replies, await collect

    bad_ingest, desc, replies, got = asyncio.run(main())
    assert bad_ingest["type"] == "rejected" and "[0, 1]" in bad_ingest["reason"]
    assert desc["expressions"] == ["neutral", "smile", "sad", "surprise", "anger"]
    assert replies[0]["type"] == "rejected" and "unknown expression 'joy'" in replies[0]["reason"]
    assert replies[1]["type"] == "ack" and replies[1]["controls"]["expression"][0]["intensity"]["smile"] == 1.0
    ref = speech_to_params(model, pcm.astype(np.float32) / 32768)
    assert len(got.frames) == len(ref)
    from realtime_core.fitted_maps import EXPRESSION_PARAMS

    late = got.values()[20:, 1] - ref[20:, 1]  # eased in by 0.3 s: lip_stretch widened by the smile
    rounded = ref[20:, 1] < 0  # (spread lips saturate at the smile's own width, realtime_core.expressions)
    assert rounded.any()
    np.testing.assert_allclose(late[rounded], EXPRESSION_PARAMS[0, 1], atol=1e-5)


def test_stalled_viewer_does_not_delay_a_healthy_one(model, head):
    pcm = _int16(speechlike(2.5, 16000, seed=7))
    n_frames = len(speech_to_params(model, pcm.astype(np.float32) / 32768))

    async def main():
        async with running(
            model, head, viewer_queue=4, viewer_max_behind_s=0.3, viewer_socket_buffer_bytes=4096, close_timeout_s=20
        ) as srv:
            url = srv.url
            async with IngestClient(url, session="s", sample_rate_hz=16000) as ing:
                # The stalled viewer: tiny receive buffer, reads the description and then nothing.
                sock = socket.socket()
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
                sock.connect(("127.0.0.1", srv.port))
                stalled = await connect(
                    ws_url(url, "/view?session=s&kind=deltas&encoding=float16"),
                    sock=sock,
                    compression=None,
                    max_size=None,
                    max_queue=1,
                )
                await stalled.recv()
                async with ViewerClient(url, session="s", kind="deltas") as healthy:
                    collect = asyncio.ensure_future(healthy.collect())
                    await stream_samples(ing, pcm, realtime=True, block_s=0.02)
                    await ing.end()
                    got = await collect
                metrics = srv.metrics()
                code = None
                with contextlib.suppress(ConnectionClosed, TimeoutError):
                    while True:  # now drain the stalled one: it was closed while behind
                        await asyncio.wait_for(stalled.recv(), 5)
                code = stalled.close_code
                return got, metrics, code

    got, metrics, code = asyncio.run(main())
    assert [m.index for m in got.frames] == list(range(n_frames))  # nothing lost or delayed out
    assert metrics["viewers_closed_slow"] == 1 and metrics["dropped_messages"] > 0
    assert code == P.CLOSE_TOO_SLOW


def test_http_endpoints(model, head):
    async def main():
        async with running(model, head) as srv:
            out = {
                p: await http_get(srv.url, p)
                for p in ("/health", "/metrics", "/head/mesh", "/head/mesh.json", "/", "/nope")
            }
            return out

    out = asyncio.run(main())
    assert out["/health"][0] == 200 and json.loads(out["/health"][1])["sessions"] == 0
    metrics = json.loads(out["/metrics"][1])
    assert {"sessions", "viewers", "dropped_messages", "timings_ms", "closes"} <= set(metrics)
    mesh = json.loads(out["/head/mesh.json"][1])
    assert len(mesh["vertices"]) == 3 * len(head.mesh.vertices) and len(mesh["triangles"]) == 3 * len(
        head.mesh.triangles
    )
    # The glTF is readable by an independent loader, with the server's vertex order intact.
    import io

    import trimesh

    scene = trimesh.load(io.BytesIO(out["/head/mesh"][1]), file_type="glb", process=False)
    (geom,) = scene.geometry.values()
    np.testing.assert_allclose(geom.vertices, head.mesh.vertices, atol=1e-4)
    np.testing.assert_array_equal(geom.faces, head.mesh.triangles)
    assert out["/"][0] == 200 and b"facecast" in out["/"][1]
    assert out["/nope"][0] == 404


def test_viewer_descriptions_are_made_once_per_subscription_and_stay_correct(model, head):
    """The description (~15 KB of JSON with the head) is encoded once per session and subscription:
    later viewers get the same text, which is the description of their own subscription."""
    from server import describe
    from server.protocol import parse_view_query

    async def first_message(url, query):
        async with connect(ws_url(url, "/view?" + query), compression=None) as ws:
            return await asyncio.wait_for(ws.recv(), 10)

    async def main():
        async with running(model, head) as srv, IngestClient(srv.url, session="d", sample_rate_hz=16000):
            texts = {}
            for q in ("session=d&kind=deltas&encoding=int16", "session=d&kind=deltas&encoding=int16", "session=d"):
                texts.setdefault(q, []).append(await first_message(srv.url, q))
            live = srv.sessions["d"]
            fresh = {
                q: describe.view_description(
                    live, parse_view_query(dict(p.split("=") for p in q.split("&")), token=None, has_head=True), head
                )
                for q in texts
            }
            return texts, fresh, len(live.descriptions)

    texts, fresh, cached = asyncio.run(main())
    deltas, params = texts["session=d&kind=deltas&encoding=int16"], texts["session=d"]
    assert len(deltas) == 2 and deltas[0] == deltas[1] and cached == 2
    assert json.loads(deltas[0]) == fresh["session=d&kind=deltas&encoding=int16"]
    assert json.loads(params[0]) == fresh["session=d"]
    assert json.loads(deltas[0])["values_per_frame"] == 3 * len(head.rig.moving)
    assert json.loads(params[0])["values_per_frame"] == 4


def test_a_large_block_is_processed_in_fair_slices_with_the_same_frames(model):
    pcm = _int16(speechlike(3.0, 16000, seed=9))
    ref = speech_to_params(model, pcm.astype(np.float32) / 32768)

    async def main():
        async with running(model) as srv, IngestClient(srv.url, session="big", sample_rate_hz=16000) as ing:
            async with ViewerClient(srv.url, session="big", audio=False) as view:
                collect = asyncio.ensure_future(view.collect())
                await ing.send(pcm)  # 3 s in one 96 kB message
                await ing.end()
                return await collect

    got = asyncio.run(main())
    assert [m.index for m in got.frames] == list(range(len(ref)))
    np.testing.assert_array_equal(got.values(), ref.astype(np.float32))


def test_config_from_toml(tmp_path):
    from server.errors import ServerConfigError

    good = tmp_path / "ok.toml"
    good.write_text('[server]\nport = 9000\nmax_sessions = 3\ntoken = "t"\n')
    cfg = ServerConfig.from_toml(good, port=9100, host=None)
    assert (cfg.port, cfg.max_sessions, cfg.token, cfg.host) == (9100, 3, "t", "127.0.0.1")
    for text, match in [
        ("[server]\nprot = 1\n", "unknown \\[server\\] keys \\['prot'\\]"),
        ("[server]\nmax_sessions = 0\n", "max_sessions"),
        ('[server]\nhost = "example.com"\n', "host must be an IP"),
        ("[server\n", "cannot read config"),
        # outside [server]: a misspelled table, a bare key, a second table
        ("[sever]\nport = 8850\n", "unknown top-level key or table 'sever'"),
        ('port = 8850\n[server]\ntoken = "t"\n', "unknown top-level key or table 'port'"),
        ("[server]\nport = 1\n[client]\nx = 1\n", "unknown top-level key or table 'client'"),
        # a bad value names the file (it did not: "port must be in 0..65535, got '8799'")
        ('[server]\nport = "8799"\n', "port must be an integer in 0..65535, got '8799'"),
        ('[server]\nauto_gain = "yes"\n', "auto_gain must be true or false"),
    ]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(ServerConfigError, match=match) as err:
            ServerConfig.from_toml(bad)
        assert str(err.value).startswith(f"{bad}: "), err.value
    with pytest.raises(ServerConfigError, match="not found"):
        ServerConfig.from_toml(tmp_path / "missing.toml")


def test_limits_and_start_timeout(model):
    async def main():
        async with running(model, max_sessions=1, max_viewers=1, start_timeout_s=0.2) as srv:
            url = srv.url
            async with IngestClient(url, session="one", sample_rate_hz=16000):
                second = await _expect_close(lambda: _raw(url, "/ingest", _start(session="two", token=None)))
                async with ViewerClient(url, session="one"):
                    extra = await _expect_close(lambda: ViewerClient(url, session="one").__aenter__())
            silent = await _expect_close(lambda: _raw(url, "/ingest"))
            return second, extra, silent

    second, extra, silent = asyncio.run(main())
    assert second[0] == P.CLOSE_TRY_LATER and "1 sessions" in second[1]
    assert extra[0] == P.CLOSE_TRY_LATER and "1 viewers" in extra[1]
    assert silent[0] == P.CLOSE_POLICY and "no start message" in silent[1]


@pytest.mark.parametrize(
    "layout",
    [
        pytest.param({}, id="one-process"),
        # Sessions in a connection worker process (server.shards): it loads the model and kernels.
        pytest.param({"workers": 1, "worker_mode": "connections"}, id="connection-workers", marks=pytest.mark.slow),
    ],
)
def test_shutdown_flushes_sessions_and_says_going_away(model, layout):
    pcm = _int16(speechlike(3.0, 16000, seed=11))

    async def main():
        srv = FacecastServer(model, config=ServerConfig(port=0, **layout))
        await srv.start()
        ing = await IngestClient(srv.url, session="live", sample_rate_hz=16000).__aenter__()
        view = await ViewerClient(srv.url, session="live", audio=False).__aenter__()
        collect = asyncio.ensure_future(view.collect())
        feed = asyncio.ensure_future(stream_samples(ing, pcm, realtime=True))
        await asyncio.sleep(1.0)
        await srv.stop()  # what SIGINT/SIGTERM do
        got = await collect
        try:
            await feed
            ing_code = ing.ws.close_code
        except ServerClosed as exc:
            ing_code = exc.code
        return got, ing_code

    cfg = ServerConfig(**layout)
    got, ing_code = run_on_loop(main(), process_loop(cfg.event_loop, connection_front=cfg.workers > 0))
    assert got.close_code == P.CLOSE_GOING_AWAY and ing_code == P.CLOSE_GOING_AWAY
    idx = [m.index for m in got.frames]
    assert idx == list(range(len(idx))) and 20 <= len(idx) < 90  # about 1 s of frames, none lost


def test_shutdown_tells_connections_without_a_session_why(model):
    """SIGTERM with connections that had no session yet (an ingest or text source that had not sent its start, as
    one whose enrolment is being adapted): the listener's own close gave them 1001 with no reason, while sessions'
    sources and viewers got "server shutting down"; now every connection is told so, and counted in /metrics."""

    async def main():
        srv = FacecastServer(model, config=ServerConfig(port=0))
        await srv.start()
        conns = [
            await connect(ws_url(srv.url, path), compression=None)
            for path in ("/ingest", "/ingest", "/view?session=x&wait=30")
        ]
        await asyncio.sleep(0.2)  # the handshakes done, the handlers waiting for a start (and the held viewer)
        await srv.stop()
        for ws in conns:
            with contextlib.suppress(ConnectionClosed):
                await asyncio.wait_for(ws.recv(), 5)
        return [(ws.close_code, ws.close_reason) for ws in conns], dict(srv.closes)

    closes, counted = asyncio.run(main())
    assert closes == [(P.CLOSE_GOING_AWAY, "server shutting down")] * 3, closes
    assert counted.get(P.CLOSE_GOING_AWAY) == 3, counted


@pytest.mark.slow
def test_compute_workers_give_the_same_frames_and_errors(model, head, wav48k):
    samples, rate = read_audio(wav48k)
    pcm = _int16(samples)
    ref = speech_to_params(model, resample_audio(samples, rate, model.sample_rate_hz))

    async def main():
        async with running(model, head, workers=2) as srv:
            url = srv.url
            async with IngestClient(url, session="w", sample_rate_hz=rate) as ing:
                ack = await ing.control(gain={"lip_stretch": 2.0})
                bad = await ing.control(gain={"lip_stretch": 99})
                async with ViewerClient(url, session="w", kind="deltas", audio=True) as view:
                    collect = asyncio.ensure_future(view.collect())
                    await stream_samples(ing, pcm, realtime=False)
                    ended = await ing.end()
                    got = await collect
            garbage = await _expect_close(
                lambda: _raw(url, "/ingest", _start(session="g", token=None), b"\x01\x02\x03")
            )
            return ack, bad, ended, got, garbage

    ack, bad, ended, got, garbage = asyncio.run(main())
    assert ack["controls"]["gain"]["lip_stretch"] == 2.0 and bad["type"] == "rejected"
    assert ended["frames"] == len(ref) == len(got.frames)
    want = np.array([head.rig.displacements(p * [1, 2, 1, 1]).reshape(-1) for p in ref])
    peak = np.abs(want).max(axis=1, keepdims=True)
    assert np.all(np.abs(got.values() - want) <= peak / 32767 + 1e-3 * peak)
    assert len(got.audio) > 0
    assert garbage[0] == P.CLOSE_INVALID_PAYLOAD and "not a whole number" in garbage[1]


def test_controls_pipelined_between_blocks_apply_where_they_were_sent(model):
    """Blocks may be fed straight from the connection's data callback (app.FacecastConnection's fast
    path) while a control waits for the handler: the control must still apply between the blocks it
    was sent between. Pipelined (no waiting for the ack) gives the frames of waiting for it; several
    controls in a row, and blocks of any size."""
    pcm = _int16(speechlike(1.5, 16000, seed=13))
    sizes = [320, 320, 960, 320, 4000, 320] * 20  # 20 ms blocks, and larger ones (a fair slice is 1600)
    blocks, i = [], 0
    for n in sizes:
        if i >= len(pcm):
            break
        blocks.append(pcm[i : i + n])
        i += n
    controls = {7: {"lip_stretch": 2.0}, 8: {"mouth_open": 0.5}, 20: {"lip_stretch": 0.5}}

    async def run(srv, name: str, pipelined: bool, controls=controls):
        async with IngestClient(srv.url, session=name, sample_rate_hz=16000) as ing:
            async with ViewerClient(srv.url, session=name, audio=False) as view:
                collect = asyncio.ensure_future(view.collect())
                acks = 0
                for k, block in enumerate(blocks):
                    if k in controls:
                        await ing.ws.send(json.dumps({"type": "control", "gain": controls[k]}))
                        if not pipelined:
                            assert json.loads(await ing.ws.recv())["type"] == "ack"
                        else:
                            acks += 1
                    await ing.send(block)
                for _ in range(acks):
                    assert json.loads(await ing.ws.recv())["type"] == "ack"
                await ing.end()
                return (await collect).values()

    async def main():
        async with running(model) as srv:
            plain = await run(srv, "plain", True, {})
            return plain, await run(srv, "waited", False), await run(srv, "pipelined", True)

    plain, waited, pipelined = asyncio.run(main())
    assert len(plain) == len(waited) == len(pipelined) > 40
    np.testing.assert_array_equal(waited, pipelined)
    assert not np.array_equal(plain, waited)  # the controls changed the frames


def test_a_head_resting_through_its_targets_describes_the_rest_its_frames_carry(model, head, parted_head):
    """A head whose lips are modelled apart rests through its own targets (its jaw below 0): zero weights or zero
    deltas are the head as modelled, lips apart, which the viewers showed before a session's first frame and eased
    to after its last. The description now carries the rest (``rest_values``): for every kind, the values a frame
    at mouth parameters 0 carries, decoded from the session's own encoding of such a frame; null where they are 0
    (the built-in head); OVR-15's rest is ``sil``."""
    from server.session import Frame

    async def descriptions(h, queries):
        async with running(model, h) as srv, IngestClient(srv.url, session="r", sample_rate_hz=16000):
            out = {}
            for q in queries:
                async with connect(ws_url(srv.url, "/view?session=r&" + q), compression=None) as ws:
                    out[q] = json.loads(await asyncio.wait_for(ws.recv(), 10))
            return out

    kinds = {
        "kind=morph&encoding=float32": (P.KIND_MORPH, P.ENC_FLOAT32),
        "kind=deltas&encoding=int16": (P.KIND_DELTAS, P.ENC_INT16),
        "kind=deltas&encoding=float16": (P.KIND_DELTAS, P.ENC_FLOAT16),
        "kind=params": (P.KIND_PARAMS, P.ENC_FLOAT32),
        "kind=blendshapes&encoding=arkit52": (P.KIND_ARKIT52, P.ENC_FLOAT32),
        "kind=blendshapes&encoding=ovr15": (P.KIND_OVR15, P.ENC_FLOAT32),
    }
    got = asyncio.run(descriptions(parted_head, list(kinds)))
    zero = np.zeros(4)
    for q, (kind, enc) in kinds.items():
        frame = Frame(
            index=0, media_time=0.0, params=zero, raw_params=zero, work_s=0.0, ready_perf=0.0, rig=parted_head.rig
        )
        data, count, scale = frame.payload(kind, enc)
        sent = P.decode_message(P.pack_header(kind, enc, 0, count, scale, 0.0, 0.0) + data).values
        rest = got[q]["rest_values"]
        if not np.any(sent):
            assert rest is None, q
            continue
        assert rest is not None and len(rest) == got[q]["values_per_frame"] == count, q
        # int16 and float16 round what the description gives to float32 precision
        np.testing.assert_allclose(sent, rest, atol=2e-3 * float(np.max(np.abs(rest))), err_msg=q)
    jaw = got["kind=morph&encoding=float32"]["names"].index("jawOpen")
    assert got["kind=morph&encoding=float32"]["rest_values"][jaw] == pytest.approx(-0.3, abs=0.01)
    assert got["kind=deltas&encoding=int16"]["rest_values"] is not None
    assert got["kind=params"]["rest_values"] is None and got["kind=blendshapes&encoding=arkit52"]["rest_values"] is None
    assert got["kind=blendshapes&encoding=ovr15"]["rest_values"][0] == 1.0  # sil
    # The built-in head rests at its neutral.
    plain = asyncio.run(descriptions(head, ["kind=deltas&encoding=int16"]))
    assert plain["kind=deltas&encoding=int16"]["rest_values"] is None


def test_sessions_say_which_view_kinds_this_node_serves(model, head):
    """The browser viewer asked every server for "morph" first and was refused (4400) by any whose head has no
    targets of its own, a refusal the server logged; /sessions now says what a viewer may ask for, best first."""
    from assets.heads.head import builtin_morph_head

    async def kinds(h):
        srv = FacecastServer(model, head=h, config=ServerConfig(port=0))
        await srv.start()
        try:
            status, body = await http_get(srv.url, "/sessions")
        finally:
            await srv.stop()
        assert status == 200
        return json.loads(body)["view_kinds"]

    assert asyncio.run(kinds(None)) == ["params"]
    assert asyncio.run(kinds(head)) == ["deltas", "params"]  # retargeted: vertex deltas
    assert asyncio.run(kinds(builtin_morph_head())) == ["morph", "deltas", "params"]


def test_sessions_starting_and_ending_are_logged(model, caplog):
    """A deployer saw sessions only as counts in /metrics: each start and end is one INFO line of
    ``facecast.sessions`` (the incidents of ``facecast.server`` stay rate-limited apart)."""
    import logging

    async def main():
        async with running(model) as srv, IngestClient(srv.url, session="logged", sample_rate_hz=16000) as ing:
            await stream_samples(ing, speechlike(0.5, 16000), realtime=False)
            return await ing.end()

    with caplog.at_level(logging.INFO, logger="facecast.sessions"):
        ended = asyncio.run(main())
    lines = [r.getMessage() for r in caplog.records if r.name == "facecast.sessions"]
    assert lines == [
        "session 'logged' started: ingest, 16000 Hz x 1",
        f"session 'logged' ended (1000 session ended): {ended['frames']} frames computed, 0 viewers",
    ], lines
