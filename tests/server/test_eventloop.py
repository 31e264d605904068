"""The server runs on the event loop it is configured with (``ServerConfig.event_loop``, server/eventloop.py).

``facecast serve`` processes (and a connection worker, which makes its own loop) report the loop they
run on in /metrics; a streamed session gives the same frames on either loop.
"""

from __future__ import annotations

import asyncio
import json
import sys
from urllib.request import urlopen

import pytest

from benchmarks.server_harness import ServerProcess
from server.config import ServerConfig
from server.errors import ServerConfigError
from server.eventloop import DEFAULT_EVENT_LOOP, loop_factory, process_loop, run, running_loop_name


def _metrics(url: str) -> dict:
    with urlopen(url + "/metrics", timeout=30) as r:
        return json.loads(r.read())


def test_uvloop_is_the_default_on_linux_and_installed():
    # pyproject makes uvloop a dependency on Linux: a fresh clone's server runs on it, never falling back silently.
    import importlib.util

    if sys.platform == "linux":
        assert ServerConfig().event_loop == "uvloop"
        assert importlib.util.find_spec("uvloop") is not None
    assert ServerConfig(event_loop="asyncio").event_loop == "asyncio"
    with pytest.raises(ServerConfigError, match="event_loop"):
        ServerConfig(event_loop="trio")


def test_loop_factory_makes_the_loop_it_names_whatever_the_policy():
    import uvloop

    async def kind() -> tuple[str, str]:
        return running_loop_name(), type(asyncio.get_running_loop()).__module__

    # The standard loop even where the installed policy is uvloop's (tests/server/conftest.py installs it).
    old = asyncio.get_event_loop_policy()
    asyncio.set_event_loop_policy(uvloop.EventLoopPolicy())
    try:
        assert run(kind(), "asyncio") == ("asyncio", "asyncio.unix_events")
    finally:
        asyncio.set_event_loop_policy(old)
    assert run(kind(), "uvloop")[0] == "uvloop"
    assert type(loop_factory("uvloop")()) is uvloop.Loop
    with pytest.raises(ValueError):
        loop_factory("trio")


@pytest.mark.system
@pytest.mark.slow
@pytest.mark.parametrize("loop", ["default", "asyncio", "uvloop"])
def test_serve_runs_on_the_configured_loop(model_path, loop):
    toml = "[server]\n" + ("" if loop == "default" else f'event_loop = "{loop}"\n')
    srv = ServerProcess(model_path, head=False, config_toml=toml)
    try:
        got = _metrics(srv.url)["event_loop"]
    finally:
        assert srv.stop() == 0
    assert got == (DEFAULT_EVENT_LOOP if loop == "default" else loop)


@pytest.mark.system
@pytest.mark.slow
@pytest.mark.parametrize("mode", ["compute", "connections"])
@pytest.mark.parametrize("loop", ["asyncio", "uvloop"])
def test_workers_run_on_the_configured_loop_and_stream(model_path, wav16k, loop, mode):
    """Each loop with each kind of worker: a connection worker makes its own loop of the configured kind and
    adopts the connections the front hands it; compute workers talk to the loop over pipes it polls."""
    from assets.audio import read_audio
    from tests.server.test_service import _int16, _watch_then_stream

    toml = f'[server]\nevent_loop = "{loop}"\nworkers = 2\nworker_mode = "{mode}"\n'
    srv = ServerProcess(model_path, head=False, config_toml=toml)
    samples, rate = read_audio(wav16k)
    try:
        ended, (got,) = asyncio.run(
            _watch_then_stream(srv.url, "w", _int16(samples), rate, kinds=[("params", None)], realtime=False)
        )
        m = _metrics(srv.url)
    finally:
        assert srv.stop() == 0
    if mode == "connections":
        # The front runs on asyncio's loop whatever is configured (server.eventloop.process_loop), the
        # workers on the configured one; and the session really ran in a worker (its push timings are there).
        assert m["event_loop"] == "asyncio"
        assert [w["event_loop"] for w in m["workers"]] == [loop, loop]
        assert sum(w["timings_ms"].get("push_per_frame", {}).get("count", 0) for w in m["workers"]) > 0
        assert m["timings_ms"].get("push_per_frame", {}).get("count", 0) == 0
    else:
        assert m["event_loop"] == loop
    assert ended["frames"] > 30
    assert [f.index for f in got.frames] == list(range(ended["frames"]))


def test_a_front_of_connection_workers_refuses_uvloop(model):
    """On uvloop the front would read every request itself (server.eventloop.process_loop): refused at start."""
    from server.app import FacecastServer

    async def start() -> None:
        srv = FacecastServer(model, config=ServerConfig(port=0, workers=1, worker_mode="connections"))
        try:
            await srv.start()
        finally:
            await srv.stop()

    with pytest.raises(ServerConfigError, match="asyncio"):
        run(start(), "uvloop")
    assert process_loop("uvloop", connection_front=True) == "asyncio"
    assert process_loop("uvloop", connection_front=False) == "uvloop"


@pytest.mark.system
def test_a_session_gives_the_same_frames_on_either_loop(model, wav16k):
    """One file streamed through a server on each loop: the same parameter frames, in order."""
    from assets.audio import read_audio
    from tests.live_server import running
    from tests.server.test_service import _int16, _watch_then_stream

    samples, rate = read_audio(wav16k)

    async def main() -> tuple[str, dict, list]:
        async with running(model) as srv:
            ended, (got,) = await _watch_then_stream(srv.url, "s", _int16(samples), rate, kinds=[("params", None)])
        return running_loop_name(), ended, [(m.index, m.values.tobytes()) for m in got.frames]

    got = {name: run(main(), name) for name in ("asyncio", "uvloop")}
    assert [g[0] for g in got.values()] == ["asyncio", "uvloop"]
    a, b = got["asyncio"][2], got["uvloop"][2]
    assert len(a) == got["asyncio"][1]["frames"] > 30
    assert [i for i, _ in a] == list(range(len(a)))
    assert a == b
