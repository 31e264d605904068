"""Python client of the facecast server: ingest audio, watch a session, decode frames.

Async, on python-websockets. The wire format lives in :mod:`wire.protocol` (pure, shared with
the server); ``docs/protocol.md`` describes it for other languages.

    async with IngestClient(url, session="s1", sample_rate_hz=16000) as ing:
        await stream_samples(ing, samples, realtime=True)
        await ing.end()

    async with ViewerClient(url, session="s1", kind="params") as view:
        async for msg in view:       # wire.protocol.Message, frames and audio
            ...
"""

from __future__ import annotations

import asyncio
import base64
import json
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlencode, urlsplit

import numpy as np
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI

from assets.pacing import paced_blocks
from clients.errors import ClientError
from wire import protocol as P


class ServerClosed(ClientError):
    """The server closed the connection with a code and reason (e.g. 4004 no such session)."""

    def __init__(self, code: int | None, reason: str) -> None:
        # code None: the connection ended without a close frame (it read "closed the connection: None ...").
        closed = f"server closed the connection: {code} {reason}" if code is not None else f"lost the server: {reason}"
        super().__init__(closed)
        self.code = code
        self.reason = reason


ENDPOINTS = ("/ingest", "/view", "/text")
"""The server's WebSocket endpoints (docs/protocol.md section 1)."""


def server_url(url: str, endpoint: str) -> str:
    """The server's base URL (``http://h:p`` or ``ws://h:p``, no trailing slash) from ``url``, which may
    already end in ``endpoint`` ("/ingest", "/view": the WebSocket URLs docs/protocol.md shows, e.g.
    ``ws://h:p/ingest``; given to `facecast send` it connected to /ingest/ingest, a 404). ClientError,
    in one line, for a URL ending in another endpoint or carrying a query (``/view?session=...``)."""
    u = urlsplit(url)
    if u.query or u.fragment:
        raise ClientError(f"{url}: give the server's base URL (http://HOST:PORT), without a query or fragment")
    base = url.rstrip("/")
    path = urlsplit(base).path
    for ep in ENDPOINTS:
        if path.endswith(ep):
            if ep != endpoint:
                raise ClientError(
                    f"{url}: ends in the server's {ep} endpoint, not {endpoint}: give the server's base URL "
                    "(http://HOST:PORT)"
                )
            return base[: -len(ep)]
    return base


def ws_url(base: str, path: str) -> str:
    """``http://h:p`` or ``ws://h:p`` (or either already ending in ``path``'s endpoint: :func:`server_url`)
    + path -> ``ws://h:p/path``."""
    b = server_url(base, path.split("?", 1)[0])
    if b.startswith("http://"):
        b = "ws://" + b[len("http://") :]
    elif b.startswith("https://"):
        b = "wss://" + b[len("https://") :]
    return b + path


LOST_REASON = "the connection ended without a close frame (the server process died, or the network failed)"


def _closed(exc: ConnectionClosed) -> ServerClosed:
    rcvd = exc.rcvd
    return ServerClosed(rcvd.code if rcvd else None, rcvd.reason if rcvd else LOST_REASON)


def _open(ws: ClientConnection | None) -> ClientConnection:
    """The connection of a client used inside ``async with`` (a clear error otherwise)."""
    if ws is None:
        raise ClientError("the client is not connected: use it as `async with ...`")
    return ws


class IngestClient:
    """One ingest connection: start message on enter, binary audio, controls, end.

    url: the server's base URL (http:// or ws://); session: its name; sample_rate_hz/channels: of
    the audio you send; sample_format: "pcm_s16le" or "f32le"; token: the shared secret if any;
    enrol: optional enrolment recording of the talker (raw bytes in the same rate/format/channels,
    1-120 s; the start message carries it base64-encoded, so it must fit the server's message limit);
    auto_gain: True/False asks the server to bring (or not) the input to the model's speech level, None leaves it
    to the server's default.
    """

    def __init__(
        self,
        url: str,
        *,
        session: str,
        sample_rate_hz: int,
        channels: int = 1,
        sample_format: str = "pcm_s16le",
        token: str | None = None,
        max_size: int | None = 1 << 20,
        enrol: bytes | None = None,
        auto_gain: bool | None = None,
    ) -> None:
        if sample_format not in P.SAMPLE_FORMATS:
            raise ClientError(f"sample_format must be one of {sorted(P.SAMPLE_FORMATS)}")
        self.url = ws_url(url, "/ingest")
        self.session = session
        self.sample_rate_hz = sample_rate_hz
        self.channels = channels
        self.sample_format = sample_format
        self.token = token
        self.max_size = max_size
        self.enrol = enrol
        self.auto_gain = auto_gain
        self.ws: ClientConnection | None = None
        self.started: dict = {}

    async def __aenter__(self) -> IngestClient:
        try:
            self.ws = await connect(self.url, compression=None, max_size=self.max_size)
        except OSError as exc:
            raise ClientError(f"{self.url}: cannot connect: {exc}") from None
        except InvalidURI:
            raise ClientError(f"{self.url}: not a server URL (give http://HOST:PORT)") from None
        except InvalidHandshake as exc:  # e.g. HTTP 401/403/429 instead of the upgrade
            raise ClientError(f"{self.url}: the server refused the connection: {exc}") from None
        start = {
            "type": "start",
            "session": self.session,
            "sample_rate": self.sample_rate_hz,
            "channels": self.channels,
            "format": self.sample_format,
        }
        if self.token is not None:
            start["token"] = self.token
        if self.enrol is not None:  # enrolment recording in this session's input format (server adapts its model)
            start["enrol"] = base64.b64encode(self.enrol).decode("ascii")
        if self.auto_gain is not None:
            start["auto_gain"] = self.auto_gain
        await self._send_json(start)
        self.started = await self._reply("started")
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self.ws is not None:
            await self.ws.close()

    async def _send_json(self, msg: dict) -> None:
        # A server may close before reading: an edge node with no computing node closes at once with 1013, and
        # the start's send raised websockets' ConnectionClosedError (`facecast send` ended in a traceback).
        try:
            await _open(self.ws).send(json.dumps(msg))
        except ConnectionClosed as exc:
            raise _closed(exc) from None

    async def _reply(self, *types: str) -> dict:
        try:
            msg = await _open(self.ws).recv()
        except ConnectionClosed as exc:
            raise _closed(exc) from None
        obj = json.loads(msg)
        if obj.get("type") not in types:
            raise ClientError(f"expected {types}, got {obj}")
        return obj

    def encode(self, samples: np.ndarray) -> bytes:
        """(n,) or (n, channels) float in [-1, 1] -> bytes of the session's format."""
        x = np.asarray(samples)
        if self.sample_format == "pcm_s16le":
            if x.dtype == np.int16:
                return x.astype("<i2").tobytes()
            # x 32768 is the exact inverse of the server's / 32768 (int16 WAV samples round-trip).
            return np.clip(np.rint(np.asarray(x, np.float64) * 32768.0), -32768, 32767).astype("<i2").tobytes()
        return np.asarray(x, dtype="<f4").tobytes()

    async def send(self, samples: np.ndarray | bytes) -> None:
        """Send one block (array or raw bytes already in the session's format)."""
        data = samples if isinstance(samples, (bytes, bytearray)) else self.encode(samples)
        try:
            await _open(self.ws).send(data)
        except ConnectionClosed as exc:
            raise _closed(exc) from None

    async def control(self, **controls: object) -> dict:
        """Send ``{"type": "control", **controls}``; returns the ack or rejected reply."""
        await self._send_json({"type": "control", **controls})
        return await self._reply("ack", "rejected")

    async def end(self) -> dict:
        """End the session: the server flushes the last frames and replies ``ended``."""
        await self._send_json({"type": "end"})
        return await self._reply("ended")


@dataclass
class SentBlock:
    """first: index of the block's first sample; n: samples; sent: ``time.time()`` after sending."""

    first: int
    n: int
    sent: float


async def stream_samples(
    ing: IngestClient,
    samples: np.ndarray,
    *,
    realtime: bool = True,
    block_s: float = 0.02,
    int16: np.ndarray | None = None,
    ahead_s: float = 0.0,
) -> list[SentBlock]:
    """Send ``samples`` ((n,) or (n, channels) float, or int16 when the format is pcm_s16le) in
    blocks of ``block_s`` seconds; real time paces block i to leave ``ahead_s`` before its last sample exists
    (absolute schedule on the loop clock, no drift), otherwise as fast as the socket takes them."""
    x = np.asarray(samples if int16 is None else int16)
    log: list[SentBlock] = []
    blocks = paced_blocks(x, ing.sample_rate_hz, block_s=block_s, realtime=realtime, offset_s=-ahead_s)
    async for i, block in blocks:
        await ing.send(block)
        log.append(SentBlock(i, len(block), time.time()))
    return log


async def stream_source(ing: IngestClient, source) -> int:
    """Forward an audio source of :mod:`server.sources` (microphone, paced file: async iterators of
    (n, channels) float32 blocks) to a remote session; returns the samples sent. The same sources
    feed local sessions through ``FacecastServer.run_source``."""
    n = 0
    async for block in source:
        await ing.send(np.asarray(block, dtype=np.float32))
        n += len(block)
    return n


async def ingest_file(
    url: str,
    path: str | Path,
    *,
    session: str,
    realtime: bool = True,
    block_s: float = 0.02,
    token: str | None = None,
    hold_s: float = 0.0,
    enrol: str | Path | None = None,
    auto_gain: bool | None = None,
    ahead_s: float = 0.0,
) -> tuple[dict, dict]:
    """Stream a WAV/FLAC/... file (mono mixdown by the reader) as one session, in real time (``ahead_s`` ahead of
    it) or as fast as the socket takes it; returns the ``started`` and ``ended`` replies. hold_s: seconds between
    the session's start and its first audio, in which viewers waiting for it connect; enrol: a recording of the
    talker (any rate/format the reader takes) sent as the start's enrolment, converted to this session's input (the
    speech file's rate, mono, pcm_s16le); auto_gain: the start's ``auto_gain`` (None: the server's default)."""
    from shlex import quote

    from assets.audio import read_audio
    from realtime_core.adaptation import MAX_ENROL_S, MIN_ENROL_S
    from realtime_core.features.resample import resample_audio

    samples, rate = read_audio(path)
    ingest = IngestClient(url, session=session, sample_rate_hz=rate, token=token, auto_gain=auto_gain)
    if enrol is not None:
        voice, voice_rate = read_audio(enrol)
        if len(voice) / voice_rate > MAX_ENROL_S:  # refused by the server too, but only after a 1009 for its size
            raise ClientError(
                f"{enrol}: {len(voice) / voice_rate:.1f} s of speech; an enrolment takes {MIN_ENROL_S:g}-"
                f"{MAX_ENROL_S:g} s (30-60 s intended): cut it, e.g. ffmpeg -i {quote(str(enrol))} -t 60 OUT.wav"
            )
        # The enrolment must be in the session's own rate/format/channels (docs/protocol.md, `enrol`): the
        # server's resampler (resample_poly) on the whole recording, then the session's s16 encoding.
        ingest.enrol = ingest.encode(resample_audio(voice, voice_rate, rate))
    try:
        async with ingest as ing:
            await asyncio.sleep(hold_s)
            await stream_samples(ing, samples, realtime=realtime, block_s=block_s, ahead_s=ahead_s)
            return ing.started, await ing.end()
    except ServerClosed as exc:
        if ingest.enrol is not None and exc.code == P.CLOSE_BAD_REQUEST and exc.reason.startswith("enrol"):
            # Named by file, without the reason's "Recorded at RATE Hz?": that asks a client which may have declared
            # the wrong rate, and this one converted the recording to the session's rate itself (40 s of music was
            # answered "... (a tone, noise or music?) Recorded at 22050 Hz?").
            why = re.sub(r" Recorded at \d+ Hz\?$", "", exc.reason)
            raise ClientError(
                f"{enrol}: the server refused it as the enrolment ({exc.code} {why}); give a recording of the talker's "
                "speech (30-60 s)"
            ) from None
        if exc.code != P.CLOSE_TOO_BIG or ingest.enrol is None:
            raise
        # The start carries the enrolment at the speech's rate: 45 s at 48 kHz is 5.8 MB, over a server's default
        # 4 MiB, and the close said only "1009 frame with 5760108 bytes exceeds limit of 4194304 bytes".
        raise ClientError(
            f"{enrol}: the enrolment, {len(voice) / voice_rate:.1f} s sent at {rate} Hz (the speech's rate), is "
            f"over the server's message limit ({exc.code} {exc.reason}; 4 MiB by default holds 60 s at 16-24 kHz): "
            f"give a shorter recording, the speech at a lower rate (ffmpeg -i {quote(str(path))} -ar 16000 OUT.wav), "
            "or raise the server's max_message_bytes"
        ) from None


@dataclass
class Received:
    """What a viewer got: the description, frames and audio (decoded), receipt times
    (``time.time()``, parallel to ``frames``), and the close code/reason."""

    description: dict = field(default_factory=dict)
    frames: list[P.Message] = field(default_factory=list)
    audio: list[P.Message] = field(default_factory=list)
    received: list[float] = field(default_factory=list)
    close_code: int | None = None
    close_reason: str = ""

    def values(self) -> np.ndarray:
        """(n_frames, values_per_frame) float32."""
        return np.array([m.values for m in self.frames]).reshape(len(self.frames), -1)

    def audio_samples(self) -> np.ndarray:
        return np.concatenate([m.values for m in self.audio]) if self.audio else np.zeros(0, np.float32)


class ViewerClient:
    """Watch a session: ``async with`` receives the description; iterate for decoded messages.

    kind: "params", "deltas", "blendshapes" or "morph"; encoding: see docs/protocol.md (None = the kind's
    default); audio: also receive the session's audio; wait_s: how long the server may hold the viewer for a
    session that has not started (0: refused with 4004 at once; docs/protocol.md section 3, ``wait``).
    """

    def __init__(
        self,
        url: str,
        *,
        session: str,
        kind: str = "params",
        encoding: str | None = None,
        audio: bool = True,
        token: str | None = None,
        max_size: int | None = 64 << 20,
        wait_s: float = 0.0,
    ) -> None:
        q = {"session": session, "kind": kind, "audio": "1" if audio else "0"}
        if encoding is not None:
            q["encoding"] = encoding
        if wait_s > 0:
            q["wait"] = f"{wait_s:.3f}"
        if token is not None:
            q["token"] = token
        self.url = ws_url(url, "/view?" + urlencode(q))
        self.max_size = max_size
        self.ws: ClientConnection | None = None
        self.description: dict = {}
        self.close_code: int | None = None
        self.close_reason = ""

    async def __aenter__(self) -> ViewerClient:
        try:
            self.ws = await connect(self.url, compression=None, max_size=self.max_size)
        except InvalidURI:
            raise ClientError(f"{self.url}: not a server URL (give http://HOST:PORT)") from None
        except InvalidHandshake as exc:  # e.g. HTTP 401/403/404/429 instead of the upgrade: was a traceback
            raise ClientError(f"{self.url}: the server refused the connection: {exc}") from None
        try:
            self.description = json.loads(await self.ws.recv())
        except ConnectionClosed as exc:
            raise _closed(exc) from None
        except BaseException:  # cancelled (a window closing) or a bad description: no connection left open
            await asyncio.shield(self.ws.close())
            raise
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self.ws is not None:
            await self.ws.close()

    async def __aiter__(self):
        while True:
            try:
                data = await _open(self.ws).recv()
            except ConnectionClosed as exc:
                self.close_code = exc.rcvd.code if exc.rcvd else None
                self.close_reason = exc.rcvd.reason if exc.rcvd else ""
                return
            if isinstance(data, str):
                raise ClientError(f"unexpected text message from the server: {data[:80]}")
            yield P.decode_message(data)

    async def collect(self) -> Received:
        """Receive until the server closes; returns everything decoded."""
        out = Received(description=self.description)
        async for m in self:
            if m.kind == P.KIND_AUDIO:
                out.audio.append(m)
            else:
                out.frames.append(m)
                out.received.append(time.time())
        out.close_code, out.close_reason = self.close_code, self.close_reason
        return out


async def http_get(url: str, path: str) -> tuple[int, bytes]:
    """Minimal HTTP/1.1 GET over asyncio streams (no extra dependency): (status, body)."""
    u = urlsplit(url if "://" in url else "http://" + url)
    reader, writer = await asyncio.open_connection(u.hostname, u.port or 80)
    writer.write(f"GET {path} HTTP/1.1\r\nHost: {u.hostname}\r\nConnection: close\r\n\r\n".encode())
    await writer.drain()
    data = await reader.read()
    writer.close()
    head, _, body = data.partition(b"\r\n\r\n")
    status = int(head.split(b" ", 2)[1])
    return status, body
