"""Video files through ffmpeg: the stream list (ffprobe), the decoded RGB frames and when each frame is
shown on the audio's clock.

The one video decoder: the face extractor (``training.video``) measures lips on these frames and
``facecast render --beside`` shows them next to the animated head, so both read a frame at the same
media time.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from assets.errors import MissingDependencyError, NotVideoError, TruncatedFileError


def ffmpeg_tool(name: str) -> str:
    """Path of ``ffmpeg`` or ``ffprobe``; MissingDependencyError when it is not installed."""
    path = shutil.which(name)
    if path is None:
        raise MissingDependencyError(f"{name} is not installed (Debian package ffmpeg)")
    return path


def probe(path: Path) -> dict:
    """ffprobe's stream list of ``path`` as {"video": {...}|None, "audio": {...}|None, "format": {...}}."""
    cmd = [
        ffmpeg_tool("ffprobe"),
        "-v",
        "error",
        "-show_entries",
        "stream=codec_type,width,height,r_frame_rate,avg_frame_rate,start_time,duration,sample_rate,nb_frames"
        ":format=duration",
        "-of",
        "json",
        str(path),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        msg = proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"ffprobe exit {proc.returncode}"
        with path.open("rb") as fh:
            head = fh.read(12)
        # an MP4 (valid "ftyp" box first) cut before its index (moov) was written
        if "moov atom not found" in proc.stderr and head[4:8] == b"ftyp":
            raise TruncatedFileError(path, "truncated video: the MP4 index (moov atom) is missing")
        raise NotVideoError(path, f"not a video: ffprobe cannot read it ({msg})")
    doc = json.loads(proc.stdout or "{}")
    streams = doc.get("streams", [])
    pick = lambda kind: next((s for s in streams if s.get("codec_type") == kind), None)  # noqa: E731
    return {"video": pick("video"), "audio": pick("audio"), "format": doc.get("format", {})}


def frame_rate(stream: dict) -> float:
    """Frames per second of a probed video stream (its average rate, else its base rate); 0 when unknown."""
    for key in ("avg_frame_rate", "r_frame_rate"):
        v = stream.get(key, "0/0")
        try:
            f = Fraction(v)
        except (ValueError, ZeroDivisionError):
            continue
        if f > 0:
            return float(f)
    return 0.0


def frame_times(info: dict, n_frames: int, fps: float) -> np.ndarray:
    """(n_frames,) float64 seconds at which frame j of a probed file is shown, on its audio's clock:
    ``start_video - start_audio + j / fps`` (a container may start the picture after the sound)."""
    v, a = info["video"] or {}, info["audio"] or {}
    start_v = float(v.get("start_time") or 0.0)
    start_a = float(a.get("start_time") or 0.0)
    return start_v - start_a + np.arange(n_frames) / fps


def decode_frames(path: Path, width: int, height: int, *, scaled: bool = False) -> tuple[np.ndarray, str]:
    """(n_frames, height, width, 3) uint8 RGB frames and ffmpeg's error text (may be empty); ``scaled``:
    ffmpeg scales the pictures to width x height (otherwise they must be the file's own size)."""
    cmd = [
        ffmpeg_tool("ffmpeg"),
        "-v",
        "error",
        "-nostdin",
        "-i",
        str(path),
        "-an",
        *(["-vf", f"scale={width}:{height}"] if scaled else []),
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-vsync",
        "passthrough",
        "pipe:1",
    ]
    proc = subprocess.run(cmd, capture_output=True)
    size = width * height * 3
    n = len(proc.stdout) // size
    frames = np.frombuffer(proc.stdout[: n * size], np.uint8).reshape(n, height, width, 3)
    return frames, proc.stderr.decode(errors="replace").strip()


@dataclass(frozen=True)
class VideoFrames:
    """A video's pictures: ``frames`` (n, height, width, 3) uint8 RGB, ``times_s`` (n,) float64 seconds at
    which each is shown on the audio's clock (:func:`frame_times`)."""

    frames: np.ndarray
    times_s: np.ndarray

    def shown_at(self, t_s: np.ndarray) -> np.ndarray:
        """(len(t_s),) int index of the frame on screen at each time t_s (seconds): the last frame shown
        at or before it; the first frame before the picture starts."""
        i = np.searchsorted(self.times_s, np.asarray(t_s, dtype=np.float64) + 1e-9, side="right") - 1
        return np.clip(i, 0, len(self.frames) - 1)


def probe_picture(path: Path) -> tuple[dict, dict, float]:
    """``(probe(path), its video stream, frames per second)``; NotVideoError for a missing file, one without
    a picture or with an unknown frame rate."""
    if not path.is_file():
        raise NotVideoError(path, "not found")
    info = probe(path)
    v = info["video"]
    if v is None or int(v.get("width", 0) or 0) == 0:
        raise NotVideoError(path, "not a video: no video stream")
    fps = frame_rate(v)
    if fps <= 0:
        raise NotVideoError(path, "not a video: unknown frame rate")
    return info, v, fps


def read_video_frames(path: str | Path, *, height: int | None = None) -> VideoFrames:
    """Every picture of a video file with its time on the audio's clock; ``height``: scaled to that many
    rows, the width keeping the aspect ratio (rounded to even, as H.264's 4:2:0 needs), so a long or
    large video is held at the size it is shown. NotVideoError for a missing file, one without a picture
    or with an unknown frame rate; TruncatedFileError when nothing decodes."""
    path = Path(path)
    info, v, fps = probe_picture(path)
    width, rows = int(v["width"]), int(v["height"])
    if height is not None:
        width, rows = max(2, 2 * round(width * height / rows / 2)), height
    frames, err = decode_frames(path, width, rows, scaled=height is not None)
    if len(frames) == 0:
        raise TruncatedFileError(path, "no picture decodes" + (f" ({err[-160:]})" if err else ""))
    return VideoFrames(frames=frames, times_s=frame_times(info, len(frames), fps))
