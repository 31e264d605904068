"""Reading speech files of any common format: WAV directly, everything else through ffmpeg."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np

from training.corpus import read_wav
from training.errors import NotAudioError


def read_audio(path: str | Path, *, rate_hz: int | None = None) -> tuple[np.ndarray, int]:
    """Decode ``path`` to mono: ``(samples (n,) float32 in [-1, 1], sample_rate_hz)``.

    WAV files are read directly; other formats (FLAC, MP3, OGG, the audio of MP4/MPG
    video...) are decoded by ffmpeg at their own rate, or at ``rate_hz`` when given.
    Raises :class:`NotAudioError` (or another :class:`training.errors.FileProblem`) naming
    the file and the problem.
    """
    path = Path(path)
    if not path.is_file():
        raise NotAudioError(path, "file not found")
    if path.suffix.lower() == ".wav" and rate_hz is None:
        return read_wav(path)
    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg is None:
        raise NotAudioError(path, "decoding this format needs ffmpeg, which is not installed (apt-get install ffmpeg)")
    rate = rate_hz or _probe_rate(path)
    cmd = [ffmpeg, "-v", "error", "-nostdin", "-i", str(path), "-vn", "-ac", "1", "-ar", str(rate),
           "-f", "s16le", "-acodec", "pcm_s16le", "-"]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    if proc.returncode != 0 or not proc.stdout:
        msg = proc.stderr.decode(errors="replace").strip().splitlines()
        raise NotAudioError(path, f"ffmpeg could not decode audio ({msg[-1] if msg else 'no audio stream'})")
    samples = np.frombuffer(proc.stdout, dtype="<i2").astype(np.float32) / 32768.0
    return samples, rate


def _probe_rate(path: Path) -> int:
    """The first audio stream's sample rate (ffprobe), 16 kHz if it cannot be told."""
    ffprobe = shutil.which("ffprobe")
    if ffprobe is None:
        return 16000
    proc = subprocess.run(
        [ffprobe, "-v", "error", "-select_streams", "a:0", "-show_entries", "stream=sample_rate",
         "-of", "default=noprint_wrappers=1:nokey=1", str(path)],
        capture_output=True, check=False, text=True,
    )
    try:
        return int(proc.stdout.strip().splitlines()[0])
    except (ValueError, IndexError):
        raise NotAudioError(path, "no audio stream found") from None
