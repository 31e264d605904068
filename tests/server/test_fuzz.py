"""Fuzzing the wire protocol against a live server with hypothesis (fixed budget: about 20 s in all).

Random and mutated messages of every kind (start messages with wrong fields and types, binary
audio of any length, controls, unknown types, deep or huge JSON, viewer queries) go to a real
server on loopback while a healthy session streams through it. Every hostile connection must end
with a close code from docs/protocol.md and a short reason free of tracebacks; never 1011. The
server stays up and the healthy session loses no frame.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
import urllib.parse
import urllib.request

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from websockets.exceptions import ConnectionClosed, InvalidStatus, InvalidURI
from websockets.sync.client import connect

from clients.client import IngestClient, ViewerClient, stream_samples
from realtime_core.pipeline import speech_to_params
from server.app import FacecastServer
from server.config import ServerConfig
from server.eventloop import loop_factory, process_loop
from tests.speech import speechlike
from wire import protocol as P

# Hypothesis against a live server over loopback (about 20 s per server layout).
pytestmark = [pytest.mark.system, pytest.mark.slow]

DOCUMENTED = {
    P.CLOSE_NORMAL,
    P.CLOSE_UNSUPPORTED_DATA,
    P.CLOSE_INVALID_PAYLOAD,
    P.CLOSE_POLICY,
    P.CLOSE_TOO_BIG,
    P.CLOSE_TRY_LATER,
    P.CLOSE_UNAUTHORIZED,
    P.CLOSE_NOT_FOUND,
    P.CLOSE_CONFLICT,
    P.CLOSE_BAD_REQUEST,
    P.CLOSE_TOO_FAST,
}
BUDGET_S = 14.0  # fuzzing time; the healthy session streams a few seconds longer

json_leaf = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**40), 2**40), st.floats(allow_nan=False), st.text(max_size=20)
)
json_value = st.recursive(
    json_leaf,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)


def _start_messages():
    good = {"type": "start", "session": "fz", "sample_rate": 16000, "format": "pcm_s16le"}
    field = st.sampled_from(["type", "session", "sample_rate", "format", "channels", "token", "batch", "input", "x"])
    mutated = st.builds(
        lambda k, v, drop: {**{a: b for a, b in good.items() if a != drop}, k: v},
        field,
        json_value,
        st.sampled_from([None, "type", "session", "sample_rate"]),
    )
    return st.one_of(
        st.just(good),
        mutated,
        st.builds(
            lambda r, f, c: {**good, "sample_rate": r, "format": f, "channels": c},
            st.integers(0, 400000),
            st.sampled_from(["pcm_s16le", "f32le", "mp3"]),
            st.integers(-1, 10),
        ),
    ).map(json.dumps)


text_messages = st.one_of(
    st.builds(
        lambda d: json.dumps({"type": "control", **d}),
        st.dictionaries(st.sampled_from(["gain", "smoothing_ms", "eyebrows"]), json_value, max_size=3),
    ),
    st.just(json.dumps({"type": "end"})),
    json_value.map(json.dumps),
    st.text(max_size=50),
    st.integers(1, 3000).map(lambda n: "[" * n + "]" * n),
)
binary_messages = st.one_of(st.binary(max_size=4000), st.integers(0, 2000).map(lambda n: b"\x00\x01" * n))
first_messages = st.one_of(_start_messages(), text_messages, binary_messages)
later_messages = st.lists(st.one_of(text_messages, binary_messages), max_size=5)
view_queries = st.dictionaries(
    st.sampled_from(["session", "kind", "encoding", "audio", "token", "wait", "zz"]), st.text(max_size=12), max_size=5
)


class _Server:
    def __init__(self, model, workers: int = 0) -> None:
        self.srv = FacecastServer(
            model,
            config=ServerConfig(
                port=0,
                start_timeout_s=1.0,
                idle_timeout_s=1.0,
                max_message_bytes=1 << 16,
                close_timeout_s=0.5,
                max_view_wait_s=0.1,  # a fuzzed `wait` that parses holds its viewer this long at most
                workers=workers,
                worker_mode="connections",
            ),
        )
        cfg = self.srv.config
        front = cfg.workers > 0 and cfg.worker_mode == "connections"
        self.loop = loop_factory(process_loop(cfg.event_loop, connection_front=front))()  # as `facecast serve`
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.call(self.srv.start())
        self.url = self.srv.url

    def call(self, coro, timeout: float = 60.0):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def metrics(self) -> dict:
        """/metrics as a client reads it (with connection workers: summed over the front and them)."""
        with urllib.request.urlopen(self.url + "/metrics", timeout=10) as r:
            return json.loads(r.read())

    def stop(self) -> None:
        self.call(self.srv.stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)


def _check_close(ws) -> None:
    code, reason = ws.close_code, ws.close_reason or ""
    assert code in DOCUMENTED, (code, reason)
    assert len(reason.encode()) <= 123 and "Traceback" not in reason and 'File "' not in reason


def _converse(url: str, path: str, messages: list) -> None:
    try:
        with connect(
            url.replace("http", "ws") + path, compression=None, open_timeout=5, close_timeout=1, max_size=None
        ) as ws:
            for m in messages:
                ws.send(m)
            if not messages or isinstance(messages[-1], bytes) or "end" not in str(messages[-1]):
                ws.send(json.dumps({"type": "end"}))  # a well-behaved finish if the session is still open
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline:
                ws.recv(timeout=deadline - time.monotonic())
    except (ConnectionClosed, TimeoutError):
        pass
    except (InvalidStatus, InvalidURI):
        return  # refused before the handshake (an HTTP status): fine
    _check_close(ws)


@pytest.fixture(scope="module", params=[0, 2], ids=["one-process", "connection-workers"])
def fuzz_server(model, request):
    """The server fuzzed: one process, and a front with two connection workers (server.shards: the
    front peeks at every request line and hands ingests and views over)."""
    s = _Server(model, workers=request.param)
    yield s
    s.stop()


def test_fuzz_ingest_and_view_against_a_live_server(model, fuzz_server):
    url = fuzz_server.url
    pcm = np.rint(speechlike(BUDGET_S + 2, 16000, seed=21) * 32767).astype(np.int16)
    ref = speech_to_params(model, pcm.astype(np.float32) / 32768)

    async def healthy():
        async with IngestClient(url, session="healthy", sample_rate_hz=16000) as ing:
            async with ViewerClient(url, session="healthy", audio=False) as view:
                collect = asyncio.ensure_future(view.collect())
                await stream_samples(ing, pcm, realtime=True, block_s=0.02)
                ended = await ing.end()
                return ended, await collect

    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(out=asyncio.run(healthy())), daemon=True)
    thread.start()
    t_end = time.monotonic() + BUDGET_S
    done = {"ingest": 0, "view": 0}

    @settings(max_examples=400, deadline=None, database=None, derandomize=True, suppress_health_check=list(HealthCheck))
    @given(first=first_messages, later=later_messages)
    def ingest(first, later):
        if time.monotonic() < t_end - BUDGET_S / 3:
            _converse(url, "/ingest", [first, *later])
            done["ingest"] += 1

    @settings(max_examples=300, deadline=None, database=None, derandomize=True, suppress_health_check=list(HealthCheck))
    @given(query=view_queries, talk=st.lists(st.one_of(st.text(max_size=5), st.binary(max_size=5)), max_size=1))
    def view(query, talk):
        if time.monotonic() < t_end:
            _converse(url, "/view?" + urllib.parse.urlencode(query), talk)
            done["view"] += 1

    # Hypothesis has no time budget of its own: each test stops doing work once its share is spent
    # (the remaining examples return at once).
    ingest()
    view()
    thread.join(60)
    ended, got = result["out"]
    assert ended["frames"] == len(ref)
    assert [m.index for m in got.frames] == list(range(len(ref)))  # the healthy session lost no frame
    assert done["ingest"] >= 30 and done["view"] >= 30, done  # the budget bought real work
    metrics = fuzz_server.metrics()
    print(f"fuzz: {done} conversations; closes by code {metrics['closes']}")
    assert "1011" not in metrics["closes"], metrics["closes"]
    assert metrics["sessions"] == 0


def test_hostile_sender_of_the_soak_benchmark_is_answered_by_documented_refusals(model, fuzz_server):
    """The soak benchmark's hostile sender against a live server while a healthy session streams:
    every invalid control it pipelines is answered without closing, every closing message gets a
    documented close code (the server's own tally holds at least what the client saw), refused
    requests get an HTTP status, and the healthy session loses no frame."""
    from benchmarks.server_soak import HostileTally, hostile_traffic

    url = fuzz_server.url
    before = dict(fuzz_server.metrics()["closes"])
    pcm = np.rint(speechlike(10.0, 16000, seed=22) * 32767).astype(np.int16)
    ref = speech_to_params(model, pcm.astype(np.float32) / 32768)
    tally = HostileTally()
    target = 400

    async def run():
        async with IngestClient(url, session="calm", sample_rate_hz=16000) as ing:
            async with ViewerClient(url, session="calm", audio=False) as view:
                collect = asyncio.ensure_future(view.collect())
                t_stop = time.monotonic() + 6.0  # the sender stops at the target or after 6 s of the 10 s of audio

                def stop() -> bool:
                    return sum(tally.answered.values()) >= target or time.monotonic() > t_stop

                hostile = asyncio.ensure_future(hostile_traffic(url, ["calm"], stop=stop, tally=tally, workers=4))
                await stream_samples(ing, pcm, realtime=True, block_s=0.02)
                ended = await ing.end()
                await hostile
                return ended, await collect

    ended, got = asyncio.run(run())
    report = tally.report()
    print(f"hostile sender: {report}")
    assert ended["frames"] == len(ref)
    assert [m.index for m in got.frames] == list(range(len(ref)))  # the healthy session lost no frame
    assert report["answered"] >= 100, report  # the sender did real work while the session streamed
    assert set(report["answered_by_scenario"]) == {
        "ingest_controls",
        "ingest_first",
        "viewer_controls",
        "viewer_query",
        "bad_request",
    }
    assert report["connections_unanswered"] == {}, report["connections_unanswered"]
    codes = {int(k): v for k, v in report["close_codes"].items()}
    assert set(codes) <= DOCUMENTED, codes
    statuses = set(report["http_status"]) - {"closed without a status"}
    assert statuses <= {"400", "403", "404", "414", "426", "429", "431"}, statuses
    after = fuzz_server.metrics()["closes"]
    assert "1011" not in after, after
    server_side = {int(k): v - before.get(k, 0) for k, v in after.items()}
    for code in (
        P.CLOSE_UNSUPPORTED_DATA,
        P.CLOSE_INVALID_PAYLOAD,
        P.CLOSE_POLICY,
        P.CLOSE_NOT_FOUND,
        P.CLOSE_BAD_REQUEST,
    ):
        assert codes.get(code, 0) <= server_side.get(code, 0), (code, codes, server_side)
    # Each pipelined invalid control got its own reply and each connection's last message its close.
    assert report["answered_by_scenario"] == report["sent_by_scenario"]
