"""``facecast demo``: the whole product on built-in defaults, no microphone or files needed.

Synthesises a few sentences with espeak-ng (or listens to the default microphone), starts the
server, streams the audio through a live session in real time while an in-process viewer watches it
over loopback like any other client, prints the URLs to open, then renders what the viewer received
(mouth parameters on the rigged head, with the relayed audio) to an MP4.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from server.errors import AudioSourceError, ServerConfigError, ServerError

if TYPE_CHECKING:
    from server.app import FacecastServer

SENTENCES: tuple[str, ...] = (
    "Hello! This face is driven by speech alone, in real time.",
    "Every thirty three milliseconds, the server turns sound into mouth movements.",
    "Peter Piper picked a peck of pickled peppers, and the lips close for every p.",
)


@dataclass(frozen=True, kw_only=True)
class DemoConfig:
    """host/port: where the server listens (port 0: any free port); mic: listen to the default
    microphone instead of synthesised speech; mic_seconds: stop the microphone after this long
    (None: at Ctrl-C); sentences: what espeak-ng says; voice: espeak voice name (en-us, en, ...);
    video: MP4 to write (None: no video); width/height: video size in pixels; web_root: served at /;
    node_modules: npm packages directory (three.js for the browser viewer, see ServerConfig)."""

    host: str = "127.0.0.1"
    port: int = 8765
    mic: bool = False
    mic_seconds: float | None = None
    sentences: tuple[str, ...] = SENTENCES
    voice: str = "en-us"
    video: Path | None = Path("facecast_demo.mp4")
    width: int = 640
    height: int = 480
    web_root: Path | None = None
    node_modules: Path | None = None

    def __post_init__(self) -> None:
        if not self.sentences and not self.mic:
            raise ServerConfigError("the demo needs at least one sentence")
        if self.mic_seconds is not None and not 0 < self.mic_seconds <= 3600:
            raise ServerConfigError(f"mic_seconds must be in (0, 3600], got {self.mic_seconds}")


@dataclass
class DemoResult:
    """What the demo's viewer received: params (n, 4) float32 per frame, audio (m,) float32 at
    audio_rate_hz; the URL that was served; speech (k,) float32 at speech_rate_hz: the synthesised
    input (None with the microphone; espeak-ng's output varies slightly from run to run)."""

    params: np.ndarray
    audio: np.ndarray
    audio_rate_hz: int
    url: str
    speech: np.ndarray | None = None
    speech_rate_hz: int = 0


def synthesise(sentences: tuple[str, ...], voice: str, *, pause_s: float = 0.5) -> tuple[np.ndarray, int]:
    """espeak-ng speech of the sentences with pauses: ((n,) float32 in [-1, 1], rate Hz)."""
    from assets.espeak import LANGUAGES, Voice, synthesizer
    from training.errors import TrainingError

    lang = next((k for k, v in LANGUAGES.items() if voice in v), None)
    if lang is None:
        raise ServerConfigError(f"unknown espeak voice {voice!r}; known: {sorted(sum(LANGUAGES.values(), ()))}")
    try:
        synth = synthesizer()
        parts = []
        for text in sentences:
            s = synth.synthesize(text, Voice(language=lang, base=voice, rate_wpm=160))
            parts += [s.samples.astype(np.float32) / 32768.0, np.zeros(int(pause_s * s.sample_rate_hz), np.float32)]
        rate = synth.sample_rate_hz
    except TrainingError as exc:
        raise AudioSourceError(f"speech synthesis failed: {exc}") from None
    lead = np.zeros(int(0.3 * rate), np.float32)  # a closed mouth before the first word
    return np.concatenate([lead, *parts]), rate


async def _gated(source, gate: asyncio.Event):
    """Start pulling the source (and its real-time clock) only once the viewer is attached."""
    await gate.wait()
    async for block in source:
        yield block


def _announce(line: str) -> None:
    """Print at once: piped (`| tee`, nohup, CI) stdout is block-buffered, and the URLs and "speak now"
    appeared only after the session had ended and the server was gone."""
    print(line, flush=True)


async def _serve(config: DemoConfig, model, head) -> FacecastServer:
    """The demo's server on ``config``'s host, port, web root and node_modules, started."""
    from server.app import FacecastServer
    from server.config import ServerConfig

    server = FacecastServer(
        model,
        head=head,
        config=ServerConfig(
            host=config.host, port=config.port, web_root=config.web_root, node_modules=config.node_modules
        ),
    )
    await server.start()
    return server


async def run_demo(config: DemoConfig, model, head, *, announce=_announce) -> DemoResult:
    """Serve, stream one live session, watch it as a client; returns what the viewer received."""
    from clients.client import ViewerClient
    from server.sources import FileSource, MicConfig, MicSource

    server = await _serve(config, model, head)
    loop = asyncio.get_running_loop()
    mic: MicSource | None = None
    source: MicSource | FileSource
    speech: np.ndarray | None = None
    try:
        if config.mic:
            mic = MicSource(MicConfig()).open()
            source, rate, what = mic, mic.sample_rate_hz, f"the default microphone at {mic.sample_rate_hz} Hz"
        else:
            speech, rate = synthesise(config.sentences, config.voice)
            source = FileSource.from_array(speech, rate, realtime=True)
            what = f"{len(config.sentences)} espeak-ng sentences ({len(speech) / rate:.1f} s)"
        gate = asyncio.Event()
        session = asyncio.ensure_future(
            server.run_source("demo", _gated(source, gate), sample_rate_hz=rate, label="demo")
        )
        while "demo" not in server.sessions:
            await asyncio.sleep(0.005)
        ws = server.url.replace("http://", "ws://")
        announce(f"facecast demo: streaming {what} through a live session")
        announce(f"  open {server.url}/   (viewer page; sessions listed)")
        announce(f"  watch {ws}/view?session=demo&kind=deltas   (or kind=params, kind=blendshapes)")
        announce(f"  metrics {server.url}/metrics")

        def on_stop() -> None:
            # End the session early: the source stops, the viewer gets the last frames, the MP4
            # covers what was streamed.
            live = server.sessions.get("demo")
            if live is not None:
                live.ended.set()
            if mic is not None:
                mic.close()

        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, on_stop)
        if mic is not None:
            announce(
                "  speak now; Ctrl-C ends the session"
                + (f" (or after {config.mic_seconds:g} s)" if config.mic_seconds else "")
            )
            if config.mic_seconds:
                loop.call_later(config.mic_seconds, on_stop)
        async with ViewerClient(server.url, session="demo", kind="params", audio=True) as viewer:
            collect = asyncio.ensure_future(viewer.collect())
            gate.set()
            await session
            got = await collect
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        url = server.url
    finally:
        if mic is not None:
            mic.close()
        await server.stop()
    audio_rate = got.description["audio"]["rate_hz"]
    return DemoResult(
        params=got.values(),
        audio=got.audio_samples(),
        audio_rate_hz=audio_rate,
        url=url,
        speech=speech,
        speech_rate_hz=0 if speech is None else rate,
    )


async def serve_replay(
    config: DemoConfig, model, head, speech: np.ndarray, rate_hz: int, *, pause_s: float = 2.0, announce=_announce
) -> int:
    """After the demo: keep serving and replay the speech as session "demo" until Ctrl-C.

    Each pass is a new live session under the same name, ``pause_s`` apart, so a browser opened
    at any time finds the head talking (the viewer reconnects when a session ends and starts
    again). Returns the number of passes played.
    """
    from server.sources import FileSource

    server = await _serve(config, model, head)
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    announce(f"facecast demo: replaying the speech every {len(speech) / rate_hz + pause_s:.0f} s until Ctrl-C")
    announce(f"  open {server.url}/ to watch and listen")
    passes = 0
    try:
        while not stop.is_set():
            source = FileSource.from_array(speech, rate_hz, realtime=True)
            session = asyncio.ensure_future(
                server.run_source("demo", aiter(source), sample_rate_hz=rate_hz, label="demo")
            )
            stopper = asyncio.ensure_future(stop.wait())
            await asyncio.wait({session, stopper}, return_when=asyncio.FIRST_COMPLETED)
            if stop.is_set():
                live = server.sessions.get("demo")
                if live is not None:
                    live.ended.set()
            await session
            stopper.cancel()
            passes += 1
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), timeout=pause_s)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
        await server.stop()
    return passes


def write_mp4(
    path: Path,
    head,
    params: np.ndarray,
    audio: np.ndarray,
    audio_rate_hz: int,
    *,
    fps: int = 30,
    width: int = 640,
    height: int = 480,
) -> Path:
    """Render params (n, 4) (IOD) on the head's rig with the offline renderer and mux audio (m,)
    float32 at audio_rate_hz into an H.264/AAC MP4 (``clients.render.video.write_video``, atomic)."""
    from assets.audio import write_wav
    from assets.files import check_writable
    from clients.errors import ClientError
    from clients.render.renderer import RenderConfig, renderer_for_rig
    from clients.render.video import VideoConfig, write_video

    path = check_writable(path)
    with tempfile.TemporaryDirectory(prefix=".facecast-demo-", dir=path.parent) as tmp:
        wav = Path(tmp) / "audio.wav"
        write_wav(wav, np.asarray(audio, dtype=np.float32), audio_rate_hz)
        try:
            with renderer_for_rig(head.rig, head.mesh, RenderConfig(width=width, height=height)) as renderer:
                return write_video(
                    params,
                    lambda p: renderer.render(head.rig.deformed(p)),
                    path,
                    size=(width, height),
                    audio=wav,
                    config=VideoConfig(fps=fps),
                )
        except ClientError as exc:
            raise ServerError(f"cannot write the video {path}: {exc}") from None
