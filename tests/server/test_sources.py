"""Audio sources for real: a file paced against the loop clock, and the microphone through a
private PulseAudio server (null sink + remapped monitor source) driving `facecast serve --mic`."""

from __future__ import annotations

import asyncio
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from assets.audio import read_audio
from clients.client import ViewerClient
from realtime_core.pipeline import speech_to_params
from server.app import FacecastServer
from server.config import ServerConfig
from server.errors import AudioSourceError
from server.sources import FileConfig, FileSource
from wire import protocol as P

# Real audio sources: files paced in real time, a private PulseAudio daemon, `facecast serve` processes.
pytestmark = pytest.mark.system


def test_file_source_real_time_and_fast_give_animate_frames(model, wav16k):
    samples, rate = read_audio(wav16k)
    samples = samples[: rate // 2]
    ref = speech_to_params(model, samples)

    async def main(realtime: bool):
        srv = FacecastServer(model, config=ServerConfig(port=0))
        await srv.start()
        try:
            src = FileSource.from_array(samples, rate, realtime=realtime, block_s=0.02)
            loop = asyncio.get_running_loop()
            t0 = loop.time()
            task = asyncio.ensure_future(srv.run_source("f", src, sample_rate_hz=rate))
            while "f" not in srv.sessions:
                await asyncio.sleep(0)
            async with ViewerClient(srv.url, session="f", audio=False) as v:
                got = await v.collect()
            await task
            return got, loop.time() - t0
        finally:
            await srv.stop()

    for realtime in (True, False):
        got, elapsed = asyncio.run(main(realtime))
        # The viewer may attach a few frames late; what it got must be the reference's tail, in order.
        idx = [m.index for m in got.frames]
        assert idx == list(range(idx[0], len(ref))) and idx[0] <= 3
        np.testing.assert_array_equal(got.values(), ref[idx[0] :].astype(np.float32))
        if realtime:
            assert elapsed >= 0.5 - 0.02  # paced: cannot finish before the audio's own duration


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(AudioSourceError, match="not found"):
        FileSource(FileConfig(path=tmp_path / "nope.wav"))


def test_microphone_session_moves_the_mouth(pulse, model_path, wav16k):
    facecast = Path(sys.executable).parent / "facecast"
    proc = subprocess.Popen(
        [str(facecast), "serve", "--port", "0", "--model", str(model_path), "--no-head", "--mic"],
        env=pulse,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        url = None
        deadline = time.monotonic() + 60
        lines = []
        while url is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            m = re.search(r"listening on (http://\S+)", line)
            url = m.group(1) if m else None
        assert url, f"server did not start: {lines} {proc.stderr.read() if proc.poll() is not None else ''}"

        async def watch():
            for _ in range(200):  # the mic session appears once the device is open
                try:
                    viewer = await ViewerClient(url, session="mic").__aenter__()
                    break
                except Exception:  # noqa: BLE001 - 4004 until the session exists
                    await asyncio.sleep(0.05)
            else:
                raise AssertionError("no mic session")
            frames, audio = [], []
            play_at = None
            player = None
            async for m in viewer:
                (audio if m.kind == P.KIND_AUDIO else frames).append(m)
                if player is None and audio:
                    # The stream's first callback has delivered audio: play speech into the sink.
                    play_at = audio[-1].media_time + audio[-1].values.size / 16000
                    player = await asyncio.create_subprocess_exec("paplay", "--device=fc", str(wav16k), env=pulse)
                if player is not None and frames and frames[-1].media_time > play_at + 2.6:
                    break  # the 2 s of speech have been heard and animated
            await player.wait()
            proc.send_signal(signal.SIGTERM)  # graceful shutdown: the viewer gets 1001
            async for m in viewer:
                (audio if m.kind == P.KIND_AUDIO else frames).append(m)
            return frames, audio, play_at, viewer.close_code

        frames, audio, play_at, code = asyncio.run(asyncio.wait_for(watch(), 60))
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == P.CLOSE_GOING_AWAY
    sig = np.concatenate([m.values for m in audio])
    t_audio = np.arange(sig.size) / 16000 + audio[0].media_time
    during = sig[(t_audio > play_at + 0.3) & (t_audio < play_at + 1.8)]
    assert np.sqrt(np.mean(during**2)) > 0.02, "the microphone did not hear the played speech"
    params = np.array([m.values for m in frames])
    t = np.array([m.media_time for m in frames])
    speaking = params[(t > play_at + 0.3) & (t < play_at + 1.8)]
    # A viewer keeps a small bounded queue and drops frames it cannot take (by design); on a
    # loaded 2-core CI machine this test's viewer may fall behind, so only a few frames are
    # required, and they must move.
    assert len(speaking) >= 3 and np.ptp(speaking, axis=0).max() > 0.1, "the mouth did not move with the speech"


def test_a_source_feeds_a_remote_session_through_the_client(model, wav16k):
    from clients.client import IngestClient, stream_source

    samples, rate = read_audio(wav16k)
    samples = samples[: rate // 2]
    ref = speech_to_params(model, samples)

    async def main():
        srv = FacecastServer(model, config=ServerConfig(port=0))
        await srv.start()
        try:
            async with IngestClient(srv.url, session="remote", sample_rate_hz=rate, sample_format="f32le") as ing:
                async with ViewerClient(srv.url, session="remote", audio=False) as v:
                    collect = asyncio.ensure_future(v.collect())
                    await stream_source(ing, FileSource.from_array(samples, rate, realtime=False))
                    await ing.end()
                    return await collect
        finally:
            await srv.stop()

    got = asyncio.run(main())
    np.testing.assert_array_equal(got.values(), ref.astype(np.float32))


def test_file_session_names_are_unique_and_valid():
    """--file a/x.wav --file b/x.wav were both named "x" (the second refused without a word); a stem outside
    the session-name set (``é``) made a name admission refuses. Names match wire's SESSION_NAME."""
    from server.sources import file_session_names

    paths = [Path("a/x.wav"), Path("b/x.wav"), Path("c/x.flac"), Path("mic.wav"), Path("café au lait.wav")]
    names = file_session_names(paths, taken=["mic"])
    assert names == ["x", "x-2", "x-3", "mic-2", "caf__au_lait"]
    long = file_session_names([Path("d" * 80 + ".wav")] * 2)
    assert long == ["d" * 64, "d" * 62 + "-2"]
    assert all(P.SESSION_NAME.match(n) for n in names + long)


def _serve(model_path: Path, *extra: str) -> tuple[subprocess.Popen, str, list[str]]:
    """Start this checkout's `facecast serve --no-head` on a free port: its process, URL and its lines up to
    "listening" and one " as session " line per --file (read on a thread: a server that never prints them
    fails the test at the deadline instead of blocking it)."""
    import queue
    import threading

    proc = subprocess.Popen(
        [sys.executable, "-m", "facecast", "serve", "--port", "0", "--model", str(model_path), "--no-head", *extra],
        cwd=Path(__file__).resolve().parents[2],  # this checkout's facecast, not the venv's installed one
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    out: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [out.put(x) for x in proc.stdout], daemon=True).start()
    lines: list[str] = []
    url = None
    deadline = time.monotonic() + 60
    while not (url and sum(" as session " in x for x in lines) == extra.count("--file")):
        try:
            lines.append(out.get(timeout=max(0.0, deadline - time.monotonic())))
        except queue.Empty:
            proc.kill()
            raise AssertionError(f"no start-up lines: {lines} {proc.communicate()[1]}") from None
        m = re.search(r"listening on (http://\S+)", lines[-1])
        url = url or (m.group(1) if m else None)
    return proc, url, lines


def _stop(proc: subprocess.Popen) -> tuple[int, str]:
    """SIGINT (Ctrl-C): its exit code and everything it logged."""
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=20)
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, err


def _session_names(url: str) -> set[str]:
    import json

    from clients.client import http_get

    status, body = asyncio.run(http_get(url, "/sessions"))
    assert status == 200
    return {row["name"] for row in json.loads(body)["sessions"]}


def test_serve_streams_files_of_one_stem_as_sessions_of_their_own(model_path, wav16k, tmp_path):
    """`facecast serve --file a/x.wav --file b/x.wav`: two sessions, x and x-2, each named at start-up (the
    second was dropped: one session "x", nothing logged, Ctrl-C exit 0)."""
    import shutil

    paths = [tmp_path / d / "x.wav" for d in ("a", "b")]
    for p in paths:
        p.parent.mkdir()
        shutil.copy(wav16k, p)
    proc, url, lines = _serve(model_path, "--file", str(paths[0]), "--file", str(paths[1]))
    names = _session_names(url)  # both stream for 2 s (real time)
    code, err = _stop(proc)
    assert names == {"x", "x-2"}, (names, err)
    assert any(f"file {paths[0]} (2.0 s) as session 'x'" in x for x in lines), lines
    assert any(f"file {paths[1]} (2.0 s) as session 'x-2'" in x for x in lines), lines
    assert code == 0 and "failed" not in err, err


def test_serve_logs_a_file_session_that_fails_and_goes_on(model_path, wav16k, tmp_path):
    """A file session the server refuses (here: it is full, max_sessions 1) is logged in one line naming the
    file and the reason, and the server goes on serving (it vanished: an un-awaited task's exception)."""
    config = tmp_path / "server.toml"
    config.write_text("[server]\nmax_sessions = 1\n")
    other = tmp_path / "other.wav"
    other.write_bytes(wav16k.read_bytes())
    proc, url, _ = _serve(model_path, "--config", str(config), "--file", str(wav16k), "--file", str(other))
    names = _session_names(url)
    code, err = _stop(proc)
    failed = [x for x in err.splitlines() if "failed" in x]
    assert len(names) == 1 and len(failed) == 1, (names, err)
    refused = other if names == {wav16k.stem} else wav16k
    assert f"file {refused}: session '{refused.stem}' failed: server is full (1 sessions)" in failed[0]
    assert "Traceback" not in err and code == 0


def test_serve_refuses_a_file_no_session_takes_before_listening(model_path, tmp_path):
    """A file at a rate no session takes (4 kHz) stops `facecast serve` at start-up with one line naming it
    (exit 2), as an unreadable file does; it was accepted and its session failed unseen once listening."""
    from assets.audio import write_wav

    low = tmp_path / "low.wav"
    write_wav(low, np.zeros(4000, np.float32), 4000)
    command = ["serve", "--port", "0", "--model", str(model_path), "--no-head", "--file", str(low)]
    done = subprocess.run(
        [sys.executable, "-m", "facecast", *command],
        cwd=Path(__file__).resolve().parents[2],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and "listening" not in done.stdout
    assert done.stderr.strip().splitlines() == [
        f"facecast serve: error: --file {low}: sample_rate must be an integer in 8000..192000, got 4000"
    ]


def test_serve_says_a_token_is_required_and_that_it_stopped(model_path, tmp_path):
    """`facecast serve` with a token said nothing of it (a user found it only in the config file), and Ctrl-C printed
    nothing: the start-up lines say a token is required, and Ctrl-C ends with a line saying the server stopped."""
    config = tmp_path / "server.toml"
    config.write_text('[server]\ntoken = "secret"\nauto_gain = true\n')
    log = tmp_path / "serve.log"
    with log.open("w") as out:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "facecast",
                "serve",
                "--port",
                "0",
                "--model",
                str(model_path),
                "--no-head",
                "--config",
                str(config),
            ],
            cwd=Path(__file__).resolve().parents[2],  # this checkout's facecast
            stdout=out,
            stderr=subprocess.DEVNULL,
        )
        try:
            deadline = time.monotonic() + 60
            while "listening on" not in log.read_text() and time.monotonic() < deadline and proc.poll() is None:
                time.sleep(0.1)
            proc.send_signal(signal.SIGINT)
            code = proc.wait(timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    lines = log.read_text().splitlines()
    assert code == 0, lines
    assert any("a token is required" in x for x in lines), lines
    assert any("auto gain: every audio session's input" in x for x in lines), lines  # the config's auto_gain
    assert lines[-1].startswith("facecast serve: stopped after "), lines
