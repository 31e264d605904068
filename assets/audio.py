"""Audio files: PCM WAV read and written directly, every other format decoded through ffmpeg.

One int16 scale everywhere (the wire's): float -> int16 is ``x * 32768`` rounded and clipped to
``[-32768, 32767]``, int16 -> float is ``/ 32768``, so int16 samples round-trip exactly.
"""

from __future__ import annotations

import io
import logging
import shutil
import subprocess
import wave
from pathlib import Path

import numpy as np

from assets.errors import (
    NotAudioError,
    SilentAudioError,
    TruncatedFileError,
    UnsupportedWavError,
    WrongSampleRateError,
)
from assets.files import atomic_write_bytes
from realtime_core.features.gain import DIGITAL_SILENCE_PEAK

ACCEPTED_RATES_HZ = (8000, 11025, 16000, 22050, 24000, 32000, 44100, 48000)
"""Sample rates a corpus WAV may have (the rates microphones and codecs actually use)."""

SILENCE_PEAK = DIGITAL_SILENCE_PEAK
"""Audio whose absolute peak is below this (float full scale 1.0) counts as silent (-80 dBFS; the core's constant)."""

INT16_SCALE = 32768.0
"""float full scale 1.0 = 32768 int16 steps (the wire format's audio scale)."""


def is_silent(samples: np.ndarray) -> bool:
    """Whether ``samples`` (n,) are digital silence: their absolute peak under :data:`SILENCE_PEAK` of full
    scale (float in [-1, 1], or int16 counted against :data:`INT16_SCALE`); an empty array is silent."""
    x = np.asarray(samples)
    if not x.size:
        return True
    # The peak from the extremes, without an |x| copy in float64 (a 60 s enrolment's was 7 MB on the event loop).
    peak = max(float(x.max()), -float(x.min()))
    return peak / (INT16_SCALE if x.dtype.kind == "i" else 1.0) < SILENCE_PEAK


def to_int16(samples: np.ndarray) -> np.ndarray:
    """float in [-1, 1] (n,) -> int16 (n,): ``x * 32768`` rounded, clipped to [-32768, 32767]."""
    return np.clip(np.rint(np.asarray(samples, dtype=np.float64) * INT16_SCALE), -32768, 32767).astype(np.int16)


def wav_bytes(samples: np.ndarray, rate_hz: int) -> bytes:
    """Mono 16-bit PCM WAV file contents. ``samples``: (n,) int16 as is, or float in [-1, 1]."""
    x = np.asarray(samples)
    if x.ndim != 1:
        raise ValueError(f"audio must be mono (n,), got shape {x.shape}")
    pcm = x if x.dtype == np.int16 else to_int16(x)
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(int(rate_hz))
        w.writeframes(pcm.astype("<i2").tobytes())
    return buf.getvalue()


def write_wav(path: str | Path, samples: np.ndarray, rate_hz: int) -> Path:
    """Atomically write mono 16-bit PCM (see :func:`wav_bytes`); returns the path."""
    return atomic_write_bytes(Path(path), wav_bytes(samples, rate_hz))


def read_wav(
    path: str | Path, *, expected_rate_hz: int | None = None, check_silence: bool = True
) -> tuple[np.ndarray, int]:
    """Read a PCM WAV (8/16/24/32-bit, any channel count -> mono mean).

    Returns (samples (n,) float32 in [-1, 1], sample_rate_hz). Raises NotAudioError,
    TruncatedFileError, WrongSampleRateError or SilentAudioError naming the file.
    """
    path = Path(path)
    try:
        with path.open("rb") as fh:
            head = fh.read(12)
    except OSError as exc:
        raise NotAudioError(path, f"cannot be read ({exc.strerror or exc})") from exc
    if len(head) < 12 or head[:4] != b"RIFF" or head[8:12] != b"WAVE":
        raise NotAudioError(path, "not audio: not a RIFF/WAVE file")
    try:
        with wave.open(str(path), "rb") as w:
            ch, width, rate, n = w.getnchannels(), w.getsampwidth(), w.getframerate(), w.getnframes()
            raw = w.readframes(n)
    except (wave.Error, EOFError, RuntimeError) as exc:
        # the wave module raises EOFError when a header chunk is cut short, and a bare RuntimeError when
        # a chunk declares more bytes than its RIFF container holds (a mangled header)
        if isinstance(exc, EOFError):
            raise TruncatedFileError(path, "truncated WAV: the header ends early") from exc
        why = str(exc) or "a chunk runs past the end of the RIFF data"
        raise UnsupportedWavError(path, f"not audio: unsupported or corrupt WAV ({why})") from exc
    if len(raw) < n * ch * width:
        have = len(raw) // max(ch * width, 1)
        raise TruncatedFileError(path, f"truncated WAV: header declares {n} frames, data holds {have}")
    if width == 1:
        x = (np.frombuffer(raw, np.uint8).astype(np.float32) - 128.0) / 128.0
    elif width == 2:
        x = np.frombuffer(raw, "<i2").astype(np.float32) / INT16_SCALE
    elif width == 3:
        b = np.frombuffer(raw, np.uint8).reshape(-1, 3).astype(np.int32)
        v = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)
        x = (np.where(v >= 1 << 23, v - (1 << 24), v)).astype(np.float32) / float(1 << 23)
    elif width == 4:
        x = np.frombuffer(raw, "<i4").astype(np.float32) / float(1 << 31)
    else:
        raise NotAudioError(path, f"not audio: unsupported sample width {width} bytes")
    if ch > 1:
        x = to_mono(x.reshape(-1, ch), path)
    if rate not in ACCEPTED_RATES_HZ:
        raise WrongSampleRateError(path, f"wrong sample rate: {rate} Hz is not one of {ACCEPTED_RATES_HZ}")
    if expected_rate_hz is not None and rate != expected_rate_hz:
        raise WrongSampleRateError(path, f"wrong sample rate: file has {rate} Hz, manifest says {expected_rate_hz} Hz")
    if len(x) == 0:
        raise TruncatedFileError(path, "truncated WAV: no samples")
    if check_silence and is_silent(x):
        raise SilentAudioError(path, f"silent: peak amplitude {float(np.max(np.abs(x))):.1e} of full scale")
    return x.astype(np.float32), int(rate)


def check_audio_path(path: str | Path) -> Path:
    """``path`` as a Path when it names an existing file; else :class:`NotAudioError` saying what it is instead
    (missing, or a folder: a user giving a folder of takes is told so, not that nothing is there)."""
    path = Path(path)
    if path.is_dir():
        raise NotAudioError(path, "is a folder, not an audio file (give one file)")
    if not path.is_file():
        raise NotAudioError(path, "file not found")
    return path


def read_audio(path: str | Path, *, rate_hz: int | None = None) -> tuple[np.ndarray, int]:
    """Decode ``path`` to mono: ``(samples (n,) float32 in [-1, 1], sample_rate_hz)``.

    PCM WAV files are read directly; other formats (FLAC, MP3, OGG, the audio of MP4/MPG
    video...), WAVs in encodings the PCM reader does not decode (float, WAVE_FORMAT_EXTENSIBLE as
    24-bit and multichannel recorders write, mu-law) or at a rate outside ``ACCEPTED_RATES_HZ``
    (96 kHz) are decoded by ffmpeg at their own rate, or at ``rate_hz`` when given.
    Raises :class:`NotAudioError` (or another :class:`training.errors.FileProblem`) naming
    the file and the problem, also for a float file holding NaN or inf samples (a live session refuses them too).
    """
    path = check_audio_path(path)
    if path.suffix.lower() == ".wav" and rate_hz is None:
        try:
            # A silent clip is a take, not a mistake (a pause line): it animates a closed mouth, as an
            # mp3 of the same silence does; corpora check silence with read_wav's default.
            return read_wav(path, check_silence=False)
        except (UnsupportedWavError, WrongSampleRateError):
            pass  # a real WAV the strict corpus reader refuses: ffmpeg decodes it below
    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg is None:
        raise NotAudioError(path, "decoding this format needs ffmpeg, which is not installed (apt-get install ffmpeg)")
    codec: str | None = None
    rate = rate_hz
    if rate is None:
        rate, codec = _probe(path)
        if rate is None:
            raise NotAudioError(path, "no audio stream found")
    samples = _ffmpeg_decode(ffmpeg, path, rate, "s16le")
    if len(samples) and np.abs(samples).max() < QUIET_MIX_PEAK * INT16_SCALE:
        # Quiet as mixed: look at the channels themselves (only then: a second decode) in case they cancelled.
        pair = _ffmpeg_decode(ffmpeg, path, rate, "s16le", channels=2).reshape(-1, 2)
        mono = to_mono(pair.astype(np.float32), path)
        if np.abs(mono).max() > np.abs(samples).max() * 2:  # they did: the loudest channel (to_mono warned)
            samples = np.rint(mono).astype(np.int16)
    # 16-bit output hides NaN and inf: ffmpeg writes a NaN as -32768 on x86 (a full-scale click; 0 on ARM) and
    # +-inf as full scale. Decoding every file to float instead would change its samples (ffmpeg downmixes stereo
    # louder to float than to 16-bit), so a file that may hold them is decoded once more, to float, to look: a float
    # file (its codec, from the probe that found its rate), or, when the rate was given and no probe ran (one more
    # would double a video's decode time, 93 -> 172 ms), one whose 16-bit samples reach full scale.
    if rate_hz is None:
        may_hold_nan = codec in FLOAT_CODECS
    else:
        may_hold_nan = int(samples.min()) == -32768 or int(samples.max()) == 32767
    if may_hold_nan:
        raw = _ffmpeg_decode(ffmpeg, path, rate, "f32le")
        broken = np.flatnonzero(~np.isfinite(raw))
        if len(broken):  # a live session refuses such a block (1007): the file is refused alike, naming where
            raise NotAudioError(
                path, f"holds NaN/inf samples at {broken[0] / rate:.2f} s (written by a failed computation?)"
            )
    return samples.astype(np.float32) / INT16_SCALE, rate


CANCELLED_BY_DB = 20.0
"""Channels whose mean is this far under the loudest channel's level cancel each other: one wired (or edited) in
opposite polarity. The mean of such a stereo take is silence or near it (a user's out-of-phase file animated a
closed mouth without a word); two microphones, or a stereo mix, lose at most ~3 dB in the mean."""
QUIET_MIX_PEAK = 0.01
"""A file decoded by ffmpeg whose mono mix peaks under this (full scale 1) is decoded once more as two channels to
look for cancelling channels (:data:`CANCELLED_BY_DB`)."""

log = logging.getLogger(__name__)


def to_mono(frames: np.ndarray, path: str | Path) -> np.ndarray:
    """Frames ``(n, channels)`` float -> ``(n,)``: the channels' mean; when that mean is :data:`CANCELLED_BY_DB` under
    the loudest channel (opposite polarity), the loudest channel instead, with one warning naming ``path``."""
    mean = frames.mean(axis=1)
    level = np.sqrt(np.mean(np.square(frames, dtype=np.float64), axis=0))  # (channels,) RMS
    loudest = int(np.argmax(level))
    mixed = float(np.sqrt(np.mean(np.square(mean, dtype=np.float64))))
    if level[loudest] > 0 and mixed < level[loudest] * 10 ** (-CANCELLED_BY_DB / 20):
        how = "silent" if mixed == 0 else f"{20 * np.log10(level[loudest] / mixed):.0f} dB under channel {loudest + 1}"
        log.warning(
            "warning: %s: its channels cancel when mixed to mono (one in opposite polarity?): the mix is %s; "
            "channel %d is used",
            path,
            how,
            loudest + 1,
        )
        return frames[:, loudest].copy()
    return mean


FLOAT_CODECS = frozenset({"pcm_f16le", "pcm_f24le", "pcm_f32le", "pcm_f32be", "pcm_f64le", "pcm_f64be"})
"""ffmpeg's names of the float PCM encodings (WAV, AIFF-C, CAF, W64, Matroska...): the files that can hold NaN/inf."""


def _ffmpeg_decode(ffmpeg: str, path: Path, rate_hz: int, fmt: str, *, channels: int = 1) -> np.ndarray:
    """The first audio stream of ``path`` mixed to ``channels`` at ``rate_hz``: (n * channels,) interleaved, int16 for
    ``fmt`` "s16le", float32 for "f32le". NotAudioError with ffmpeg's last line when it cannot decode it."""
    cmd = [ffmpeg, "-v", "error", "-nostdin", "-i", str(path), "-vn", "-ac", str(channels), "-ar", str(rate_hz)]
    cmd += ["-f", fmt, "-acodec", f"pcm_{fmt}", "-"]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    if proc.returncode != 0 or not proc.stdout:
        msg = proc.stderr.decode(errors="replace").strip().splitlines()
        raise NotAudioError(path, f"ffmpeg could not decode audio ({msg[-1] if msg else 'no audio stream'})")
    return np.frombuffer(proc.stdout, dtype="<i2" if fmt == "s16le" else "<f4")


def _probe(path: Path) -> tuple[int | None, str | None]:
    """The first audio stream's (sample rate, ffmpeg's codec name) by ffprobe: (16000, None) without ffprobe (the
    rate cannot be told), (None, None) when it finds no audio stream."""
    ffprobe = shutil.which("ffprobe")
    if ffprobe is None:
        return 16000, None
    proc = subprocess.run(
        [
            ffprobe,
            "-v",
            "error",
            "-select_streams",
            "a:0",
            "-show_entries",
            "stream=sample_rate,codec_name",
            "-of",
            "default=noprint_wrappers=1",
            str(path),
        ],
        capture_output=True,
        check=False,
        text=True,
    )
    found = dict(line.split("=", 1) for line in proc.stdout.splitlines() if "=" in line)
    try:
        return int(found["sample_rate"]), found.get("codec_name")
    except (KeyError, ValueError):
        return None, None
