"""Auto gain per session: a start message's ``auto_gain`` (or the server's default) brings the input to the model's
training speech level before its features (real server over loopback, the shipped model)."""

from __future__ import annotations

import asyncio
import json
from dataclasses import replace

import numpy as np
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from clients.client import IngestClient, ViewerClient, stream_samples, ws_url
from realtime_core.features.gain import InputGainConfig
from realtime_core.pipeline import speech_to_params
from server.app import FacecastServer
from server.config import ServerConfig
from tests.speech import speechlike
from wire import protocol as P

pytestmark = pytest.mark.system  # a real server over loopback


@pytest.fixture(scope="module")
def shipped():
    from assets.modelfile import load_model

    return load_model()


def _i16(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x * 32768), -32768, 32767).astype(np.int16)


async def _session(url: str, name: str, speech: np.ndarray, auto_gain: bool | None):
    async with (
        IngestClient(url, session=name, sample_rate_hz=16000, auto_gain=auto_gain) as ing,
        ViewerClient(url, session=name, kind="params") as v,
    ):
        task = asyncio.ensure_future(v.collect())
        await stream_samples(ing, speech, realtime=False, block_s=0.1)
        await ing.end()
        return ing.started, (await task).values()


def test_a_quiet_take_with_auto_gain_moves_the_mouth_as_the_gain_stage_computes_it(shipped) -> None:
    """Speech 20 dB under the model's level opened the mouth about half as far (no way to say otherwise live). With
    ``auto_gain`` the session's frames are the offline path's with the gain stage, bit for bit, and nearer the same
    speech at its own level than without; a server whose default is on applies it unless the start says false."""
    loud = speechlike(5.0, 16000, seed=7) * 0.9
    quiet = _i16(loud * 0.1)  # -20 dB
    gained_model = replace(shipped, frontend=replace(shipped.frontend, input_gain=InputGainConfig()))
    ref_gain = speech_to_params(gained_model, quiet / 32768.0)
    ref_plain = speech_to_params(shipped, quiet / 32768.0)
    ref_loud = speech_to_params(shipped, _i16(loud) / 32768.0)

    async def main():
        out = {}
        for default in (False, True):
            srv = FacecastServer(shipped, config=ServerConfig(port=0, auto_gain=default, ingest_burst_s=60.0))
            await srv.start()
            try:
                for ask in (None, True, False):
                    out[default, ask] = await _session(srv.url, f"s{int(default)}{ask}", quiet, ask)
            finally:
                await srv.stop()
        return out

    out = asyncio.run(main())
    for (default, ask), (started, values) in out.items():
        on = default if ask is None else ask
        assert started.get("auto_gain", False) == on, (default, ask, started)
        np.testing.assert_array_equal(values, (ref_gain if on else ref_plain).astype(np.float32))
    mo = 2  # mouth_open
    err_gain = np.abs(ref_gain[:, mo] - ref_loud[:, mo]).mean()
    err_plain = np.abs(ref_plain[:, mo] - ref_loud[:, mo]).mean()
    assert err_gain < 0.5 * err_plain, (err_gain, err_plain)


def test_auto_gain_must_be_a_boolean(shipped) -> None:
    async def main():
        srv = FacecastServer(shipped, config=ServerConfig(port=0))
        await srv.start()
        try:
            async with connect(ws_url(srv.url, "/ingest"), compression=None) as ws:
                start = {"type": "start", "session": "g", "sample_rate": 16000, "auto_gain": "yes"}
                await ws.send(json.dumps(start))
                try:
                    await asyncio.wait_for(ws.recv(), 10)
                except ConnectionClosed as exc:
                    return exc.rcvd.code, exc.rcvd.reason
            return None, "not closed"
        finally:
            await srv.stop()

    assert asyncio.run(main()) == (P.CLOSE_BAD_REQUEST, "auto_gain must be true or false, got 'yes'")
