"""``facecast send``: a speech file streamed into a real server on loopback as one live session, and
what a user gets wrong (no server there, a file that is not audio, a session name already live)."""

from __future__ import annotations

import asyncio
import socket
import time

import numpy as np
import pytest

from assets.audio import read_audio, write_wav
from facecast.cli import main
from tests.live_server import LiveServer, stream_session
from tests.speech import speechlike

pytestmark = pytest.mark.system  # a real server over loopback


async def _watch(url: str, name: str):
    """A params viewer of session ``name`` from its first frame (retried until the session is live)."""
    from clients.client import ServerClosed, ViewerClient

    for _ in range(400):
        try:
            async with ViewerClient(url, session=name, kind="params", audio=False) as v:
                return await v.collect()
        except ServerClosed:  # 4004: not live yet
            await asyncio.sleep(0.005)
    raise AssertionError(f"session {name!r} never became watchable")


def test_send_streams_a_file_as_a_live_session_equal_to_animate(tmp_path, model, capsys):
    from realtime_core.pipeline import speech_to_params

    x = speechlike(1.5, 16000, seed=4)
    wav = write_wav(tmp_path / "hello.wav", x, 16000)
    srv = LiveServer(model, None)
    try:
        watched = srv.submit(_watch(srv.url, "hello"))
        assert main(["send", str(wav), srv.url]) == 0  # real time, session named after the file
        got = watched.result(30)
    finally:
        srv.stop()
    out = capsys.readouterr().out
    samples, rate = read_audio(wav)  # the 16-bit samples the file holds
    want = speech_to_params(model, samples, rate)  # what `facecast animate` computes
    assert f"session 'hello' ended: {len(want)} frames" in out, out
    assert got.close_code == 1000
    by_index = {m.index: m.values for m in got.frames}
    assert len(by_index) >= len(want) - 3  # the viewer joined within the first frames
    for k, v in by_index.items():
        np.testing.assert_allclose(v, want[k], atol=1e-5)


def test_send_fast_keeps_within_the_servers_burst(tmp_path, model, capsys):
    """A server holds an ingest to real time plus its burst (2 s): `send --fast` sent the whole file at once, so on
    a file of minutes the audio queued in the sockets with the keepalive pings behind it, and the session ended
    after 40 s with "1011 keepalive ping timeout". A server that closes an ingest running over its burst (4029)
    shows the same overrun at once: 4 s of audio was closed; now the first 1.5 s go at once, the rest in real time."""
    wav = write_wav(tmp_path / "four.wav", speechlike(4.0, 16000, seed=5), 16000)
    srv = LiveServer(model, None, ingest_overrun="close")
    try:
        assert main(["send", str(wav), srv.url, "--fast"]) == 0, capsys.readouterr().err
    finally:
        srv.stop()
    assert "session 'four' ended: 120 frames, 4.00 s of audio" in capsys.readouterr().out


def test_send_bad_inputs_say_one_line_and_exit_2(tmp_path, model, capsys):
    wav = write_wav(tmp_path / "a.wav", speechlike(0.5, 16000, seed=1), 16000)
    with socket.socket() as s:  # a port that was free a moment ago: nothing listens on it
        s.bind(("127.0.0.1", 0))
        closed = f"http://127.0.0.1:{s.getsockname()[1]}"
    notes = tmp_path / "notes.txt"
    notes.write_text("not audio\n")
    srv = LiveServer(model, None)
    try:
        live = srv.submit(stream_session(srv.url, "taken", 20.0))
        cases = [
            ([str(wav), closed], "cannot connect"),
            ([str(wav), "127.0.0.1:1"], "not a server URL"),
            ([str(tmp_path / "nope.wav"), srv.url], "nope.wav: file not found"),
            ([str(tmp_path), srv.url], "is a folder, not an audio file"),
            ([str(notes), srv.url], "notes.txt"),
        ]
        for args, want in cases:
            assert main(["send", *args]) == 2, args
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1 and want in err, (args, err)
        # Wait for the other session to be live: a send tried before its start was accepted took the name
        # itself (exit 0), and the retries after it found the name free again (a flaky failure).
        for _ in range(1000):
            if "taken" in srv.server.sessions:
                break
            time.sleep(0.01)
        assert main(["send", str(wav), srv.url, "--session", "taken", "--fast"]) == 2
        err = capsys.readouterr().err.strip()
        assert "4009" in err and "taken" in err, err
        live.cancel()
    finally:
        srv.stop()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.wav", "notes.txt"]  # nothing left behind


def test_send_accepts_the_ingest_endpoints_url_and_refuses_another_endpoint(tmp_path, model, capsys):
    """docs/protocol.md gives the ingest's URL as ws://HOST:PORT/ingest: `facecast send` given it (or
    http://HOST:PORT/ingest/) connected to /ingest/ingest and exited 2 on a 404. It streams to the
    server's /ingest; a URL naming the viewers' /view (or with a query) is refused in one line."""
    wav = write_wav(tmp_path / "a.wav", speechlike(0.5, 16000, seed=1), 16000)
    srv = LiveServer(model, None)
    try:
        ws = srv.url.replace("http://", "ws://")
        for i, (url, base) in enumerate(((f"{ws}/ingest", ws), (f"{srv.url}/ingest/", srv.url))):
            assert main(["send", str(wav), url, "--session", f"ep{i}", "--fast"]) == 0, capsys.readouterr().err
            out = capsys.readouterr().out
            assert f"session 'ep{i}' ended: 15 frames" in out and f"to {base} as fast" in out, out
        for url, want in ((f"{ws}/view", "/view endpoint"), (f"{srv.url}/ingest?session=x", "without a query")):
            assert main(["send", str(wav), url, "--fast"]) == 2, url
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1 and want in err, err
        assert srv.server.closes.get(4004, 0) == 0 and not srv.server.sessions  # the refused ones never connected
    finally:
        srv.stop()


def test_send_enrols_40_s_of_real_speech_under_the_default_message_limit(tmp_path, model, shared_data, capsys):
    """`send --enrol VOICE` carries the talker's recording in the start message, converted to the session's
    rate (here LJSpeech's 22.05 kHz -> the speech file's 16 kHz), mono, s16. 40 s (30-60 s is the intended
    amount) is 1.7 MB of base64: over the old 1 MiB default max_message_bytes (closed 1009), under the new one."""
    from server.config import ServerConfig

    wavs = sorted((shared_data / "speech" / "ljspeech").glob("LJ*.wav"))
    parts, total = [], 0
    for w in wavs:  # real speech of one talker, whole utterances up to 40 s
        x, voice_rate = read_audio(w)
        if total + len(x) > 40 * voice_rate:
            continue
        parts.append(x)
        total += len(x)
    voice = np.concatenate(parts)
    assert voice_rate == 22050 and len(voice) > 35 * voice_rate
    enrol = write_wav(tmp_path / "voice.wav", voice, voice_rate)
    at_16k = -(-len(voice) * 320 // 441)  # resample_poly's ceil(n up / down) samples
    wav = write_wav(tmp_path / "a.wav", speechlike(0.5, 16000, seed=1), 16000)
    # A server at the old 1 MiB limit refuses this start message (too big: 1009) and send says so, exit 2.
    old = LiveServer(model, None, max_message_bytes=1 << 20)
    try:
        assert main(["send", str(wav), old.url, "--enrol", str(enrol), "--fast"]) == 2
    finally:
        old.stop()
    refused = capsys.readouterr()
    assert "1009" in refused.err + refused.out, refused
    srv = LiveServer(model, None)  # today's default takes it
    assert srv.config.max_message_bytes == ServerConfig().max_message_bytes
    try:
        assert main(["send", str(wav), srv.url, "--enrol", str(enrol), "--fast"]) == 0, capsys.readouterr().err
        out = capsys.readouterr().out
        assert f"adapted the session to {at_16k / 16000:.2f} s of {enrol}" in out, out
        assert "session 'a' ended: 15 frames" in out, out
        # The same 40 s beside speech at 48 kHz is sent at 48 kHz (5.1 MB of base64): over the default limit. The
        # close said only "1009 frame with 5120108 bytes exceeds limit of 4194304 bytes"; now the line names the
        # enrolment, its rate and how to proceed.
        wav48 = write_wav(tmp_path / "a48.wav", speechlike(0.5, 48000, seed=1), 48000)
        assert main(["send", str(wav48), srv.url, "--enrol", str(enrol), "--fast"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"facecast send: error: {enrol}: the enrolment, "), err
        assert "s sent at 48000 Hz (the speech's rate), is over the server's message limit (1009 " in err[0]
        assert f"ffmpeg -i {wav48} -ar 16000 OUT.wav" in err[0]
        # Over 120 s: refused before connecting (the server refuses it too, after a 1009 for its size).
        long = write_wav(tmp_path / "long.wav", np.tile(voice, 4)[: 121 * voice_rate], voice_rate)
        assert main(["send", str(wav), srv.url, "--enrol", str(long), "--fast"]) == 2
        err = capsys.readouterr().err
        assert f"error: {long}: 121.0 s of speech; an enrolment takes 1-120 s (30-60 s intended)" in err, err
    finally:
        srv.stop()


def test_send_names_an_enrolment_the_server_refuses_without_asking_its_rate(tmp_path, capsys):
    """12 s of music-like tones as `--enrol`: the server refuses it (4400, not speech); send said "server closed the
    connection: 4400 enrol: ... (a tone, noise or music?) Recorded at 22050 Hz?", the file unnamed and a rate question
    that cannot apply (send converts the enrolment to the session's rate itself). Now one line naming the file."""
    from assets.modelfile import load_model

    t = np.arange(12 * 22050) / 22050
    tune = 0.2 * np.sin(2 * np.pi * (220 + 110 * np.floor(t * 2 % 4)) * t)  # a four-note figure, 0.5 s per note
    enrol = write_wav(tmp_path / "tune.wav", tune, 22050)
    wav = write_wav(tmp_path / "a.wav", speechlike(0.5, 22050, seed=1), 22050)
    srv = LiveServer(load_model(), None)
    try:
        assert main(["send", str(wav), srv.url, "--enrol", str(enrol), "--fast"]) == 2
    finally:
        srv.stop()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        f"facecast send: error: {enrol}: the server refused it as the enrolment (4400 enrol: it does not sound like "
        "speech: "
    ), err
    assert "Recorded at" not in err[0] and err[0].endswith("give a recording of the talker's speech (30-60 s)"), err


def _send_to(handler, wav) -> int:
    """`facecast send --fast WAV` into a bare WebSocket server on loopback whose connections ``handler``
    serves (a stand-in for a server that misbehaves in one precise way); returns the exit code."""
    from websockets.asyncio.server import serve

    async def send_to_it() -> int:
        async with serve(handler, "127.0.0.1", 0, compression=None) as server:
            port = server.sockets[0].getsockname()[1]
            return await asyncio.to_thread(main, ["send", str(wav), f"http://127.0.0.1:{port}", "--fast"])

    return asyncio.run(asyncio.wait_for(send_to_it(), 20))


def test_send_to_a_server_that_dies_says_the_connection_was_lost(tmp_path, capsys):
    """A server killed mid-session (`kill -9` of a cluster node, docs/deploy.md) drops the ingest's socket
    without a close frame: `facecast send` printed "server closed the connection: None connection lost".
    The server here is a WebSocket server whose socket goes as a killed process's does, after the start."""
    from websockets.asyncio.server import ServerConnection

    wav = write_wav(tmp_path / "a.wav", speechlike(0.5, 16000, seed=1), 16000)

    async def killed(ws: ServerConnection) -> None:
        await ws.recv()  # the start message
        ws.transport.abort()  # no close frame, as from a process killed with SIGKILL

    assert _send_to(killed, wav) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "None" not in err, err
    assert "lost the server: the connection ended without a close frame" in err, err


def test_send_to_a_server_that_refuses_before_the_start_says_its_close(tmp_path, capsys):
    """An edge node with no computing node left (docs/deploy.md) closes an ingest with 1013 as it connects,
    before the start message is read: `facecast send` ended in a traceback (websockets' ConnectionClosedError
    from sending the start). The server here closes each connection so, at once."""
    from websockets.asyncio.server import ServerConnection

    wav = write_wav(tmp_path / "a.wav", speechlike(0.5, 16000, seed=1), 16000)

    async def refusing(ws: ServerConnection) -> None:
        await ws.close(1013, "no computing node is available")

    assert _send_to(refusing, wav) == 2
    err = capsys.readouterr().err.strip()
    assert err == "facecast send: error: server closed the connection: 1013 no computing node is available", err
