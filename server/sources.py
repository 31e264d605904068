"""Audio sources as async iterators of sample blocks: the microphone and files.

Each source has ``sample_rate_hz`` and ``channels`` and yields ``(n, channels)`` float32 blocks in
[-1, 1] (the WebSocket ingest source is the ingest handler itself, in :mod:`server.app`).

Microphone: sounddevice is imported only when a microphone is opened (without the PortAudio library
the import itself fails). The PortAudio callback runs on its own thread, so it only copies the block
and hands it to the event loop with ``call_soon_threadsafe``; everything else happens on the loop.

File: decoded whole (WAV directly, other formats through ffmpeg), then either paced in real time
(block ``i`` is released when its last sample would have been captured, on an absolute schedule
against the loop clock, so sleeps never accumulate drift) or yielded as fast as the consumer takes it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from assets.pacing import paced_blocks
from server.errors import AudioSourceError, ServerConfigError


@dataclass(frozen=True, kw_only=True)
class MicConfig:
    """device: PortAudio device name or index (None = the default input); sample_rate_hz: capture
    rate (None = the device's default); channels: captured channels (mixed down by the session);
    block_s: callback block length in seconds."""

    device: str | int | None = None
    sample_rate_hz: int | None = None
    channels: int = 1
    block_s: float = 0.01

    def __post_init__(self) -> None:
        if not 1 <= self.channels <= 8:
            raise ServerConfigError(f"channels must be in 1..8, got {self.channels}")
        if not 0.001 <= self.block_s <= 1.0:
            raise ServerConfigError(f"block_s must be in [0.001, 1] s, got {self.block_s}")


def _sounddevice():
    try:
        import sounddevice
    except OSError as exc:  # sounddevice raises OSError when libportaudio is missing
        raise AudioSourceError(f"the microphone needs the PortAudio library ({exc}); install libportaudio2") from None
    except ImportError as exc:
        raise AudioSourceError(f"the microphone needs the sounddevice package ({exc})") from None
    return sounddevice


class MicSource:
    """The microphone as an async iterator of (n, channels) float32 blocks.

    ``first_block``: an asyncio.Event set when the first callback delivered audio (tests start
    playback after it). ``overflows``: blocks PortAudio reported as overrun. Use ``async with``
    or call :meth:`open` / :meth:`close`.
    """

    def __init__(self, config: MicConfig = MicConfig()) -> None:
        self.config = config
        self.first_block = asyncio.Event()
        self.overflows = 0
        self._queue: asyncio.Queue[np.ndarray | None] = asyncio.Queue()
        self._stream: Any = None  # a sounddevice.InputStream (sounddevice has no type information)
        self.sample_rate_hz = 0
        self.channels = config.channels
        self._closed = False

    def open(self) -> MicSource:
        sd = _sounddevice()
        loop = asyncio.get_running_loop()
        cfg = self.config
        try:
            info = sd.query_devices(cfg.device, "input")
        except (ValueError, sd.PortAudioError) as exc:
            which = (
                "no default input device (no microphone found?)"
                if cfg.device is None
                else (f"no usable input device {cfg.device!r}")
            )
            raise AudioSourceError(f"{which}: {exc}") from None
        rate = int(cfg.sample_rate_hz or info["default_samplerate"])
        self.sample_rate_hz = rate

        def callback(indata, frames, time_info, status) -> None:
            if status.input_overflow:
                self.overflows += 1
            loop.call_soon_threadsafe(self._deliver, indata.copy())

        try:
            self._stream = sd.InputStream(
                device=cfg.device,
                samplerate=rate,
                channels=cfg.channels,
                dtype="float32",
                blocksize=max(1, int(round(cfg.block_s * rate))),
                callback=callback,
            )
            self._stream.start()
        except (ValueError, sd.PortAudioError) as exc:
            raise AudioSourceError(f"cannot open input device {info.get('name', cfg.device)!r}: {exc}") from None
        return self

    def _deliver(self, block: np.ndarray) -> None:
        if self._closed:
            return
        self.first_block.set()
        self._queue.put_nowait(block)

    def close(self) -> None:
        if self._stream is not None and not self._closed:
            self._closed = True
            self._stream.stop()
            self._stream.close()
            self._queue.put_nowait(None)

    async def __aenter__(self) -> MicSource:
        return self.open()

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    def __aiter__(self) -> MicSource:
        return self

    async def __anext__(self) -> np.ndarray:
        if self._stream is None:
            raise AudioSourceError("MicSource used before open()")
        block = await self._queue.get()
        if block is None:
            raise StopAsyncIteration
        return block


@dataclass(frozen=True, kw_only=True)
class FileConfig:
    """path: audio file (WAV; FLAC, MP3... through ffmpeg); realtime: pace at the audio's own rate
    (False: as fast as consumed); block_s: block length in seconds."""

    path: Path
    realtime: bool = True
    block_s: float = 0.02

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        if not 0.001 <= self.block_s <= 10.0:
            raise ServerConfigError(f"block_s must be in [0.001, 10] s, got {self.block_s}")


class FileSource:
    """A file as an async iterator of (n, 1) float32 blocks (mono, the file's own rate)."""

    def __init__(self, config: FileConfig) -> None:
        from assets.audio import read_audio
        from assets.errors import AssetsError

        self.config = config
        try:
            samples, rate = read_audio(config.path)
        except AssetsError as exc:
            raise AudioSourceError(str(exc)) from None
        self.samples = np.asarray(samples, dtype=np.float32)
        self.sample_rate_hz = int(rate)
        self.channels = 1

    @classmethod
    def from_array(
        cls, samples: np.ndarray, sample_rate_hz: int, *, realtime: bool = True, block_s: float = 0.02
    ) -> FileSource:
        """The same pacing over an in-memory (n,) float array (the demo's synthesised speech)."""
        self = cls.__new__(cls)
        self.config = FileConfig(path=Path("<memory>"), realtime=realtime, block_s=block_s)
        self.samples = np.asarray(samples, dtype=np.float32).reshape(-1)
        self.sample_rate_hz = int(sample_rate_hz)
        self.channels = 1
        return self

    @property
    def duration_s(self) -> float:
        return len(self.samples) / self.sample_rate_hz

    async def __aiter__(self):
        async for _, block in paced_blocks(
            self.samples, self.sample_rate_hz, block_s=self.config.block_s, realtime=self.config.realtime
        ):
            yield block[:, None]


def file_session_names(paths: Sequence[Path], *, taken: Iterable[str] = ()) -> list[str]:
    """A session name for each file, unique among them and ``taken``: the file's stem with characters
    outside the session-name set made ``_`` (at most 64), then ``-2``, ``-3``... for a repeat
    (``a/x.wav``, ``b/x.wav`` -> ``x``, ``x-2``). Two files of one stem were one session, the second
    refused with nothing said (``facecast serve --file a/x.wav --file b/x.wav``)."""
    used = set(taken)
    names = []
    for path in paths:
        stem = "".join(c if (c.isalnum() and c.isascii()) or c in "_.-" else "_" for c in path.stem)[:64] or "file"
        name, n = stem, 1
        while name in used:
            n += 1
            suffix = f"-{n}"
            name = stem[: 64 - len(suffix)] + suffix
        used.add(name)
        names.append(name)
    return names
