"""Offline video: mouth parameters over time -> rendered frames -> MP4 with the speech muxed in.

Parameters come from a CSV (``t, upper_lip_raise, lip_stretch, mouth_open, lip_corner_depress``,
seconds and IOD units, any rate: :func:`assets.tracks.read_csv_resampled` puts them on the video's
frame grid) or from speech through the model (:func:`params_for_audio`, the real-time core's offline
path). Frames are piped raw to ffmpeg (H.264, yuv420p, AAC audio, ``-shortest``); the MP4 is written to a
temporary name next to the target and renamed when ffmpeg succeeds.
"""

from __future__ import annotations

import functools
import os
import queue
import shutil
import subprocess
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from clients.errors import RenderError
from realtime_core import VISUAL_PARAMS
from realtime_core.track import DEFAULT_FPS, Track


def params_for_audio(
    path: str | Path,
    model: str | Path | None,
    *,
    mapper: str = "hmm",
    check: Callable[[np.ndarray, int], None] | None = None,
    auto_gain: bool = False,
) -> Track:
    """Speech file -> the mouth-parameter track (F, 4) in IOD units at the model's 30 fps.

    The real-time core's offline path (``realtime_core.pipeline.speech_to_params``, the same
    computation as a live session) with the model loaded by ``assets.modelfile.load_model``
    (``model`` None = the default model); ``mapper`` "mlp" loads an MLP mapper file instead;
    ``check(samples (n,) float, rate_hz)`` is called on the decoded speech first (the command's warnings);
    ``auto_gain``: the model's front end first brings the speech to its training level
    (:func:`realtime_core.pipeline.with_auto_gain`).
    """
    from assets.audio import read_audio
    from assets.errors import FileProblem
    from assets.modelfile import load_speech_model
    from realtime_core.errors import InvalidAudioError
    from realtime_core.pipeline import speech_to_params, with_auto_gain

    av = load_speech_model(mapper, model)
    if auto_gain:
        av = with_auto_gain(av)
    samples, rate = read_audio(path)
    if check is not None:
        check(samples, rate)
    try:
        params = speech_to_params(av, samples, rate)
    except InvalidAudioError as exc:  # e.g. shorter than one analysis window: name the file
        raise FileProblem(path, str(exc)) from None
    return Track(values=np.asarray(params, dtype=np.float64)[:, : len(VISUAL_PARAMS)], fps=DEFAULT_FPS)


def with_caption(image: np.ndarray, text: str) -> np.ndarray:
    """The frame (h, w, 3) uint8 with ``text`` in small light type at the bottom left (e.g. a
    licence credit); unchanged when text is empty. The text's coverage is drawn once per (text,
    frame size) and composited with numpy (drawing it with PIL on every frame cost about as much as
    rendering a frame without anti-aliasing)."""
    if not text:
        return image
    alpha = _caption_alpha(text, image.shape[1], image.shape[0])
    out = np.array(image, dtype=np.uint8, copy=True)
    strip = out[-len(alpha) :]
    blended = strip.astype(np.float32) * (1.0 - alpha[..., None]) + 225.0 * alpha[..., None]
    strip[:] = np.rint(blended).astype(np.uint8)
    return out


@functools.lru_cache(maxsize=8)
def _caption_alpha(text: str, width: int, height: int) -> np.ndarray:
    """(rows, width) float32 coverage in [0, 1] of ``text`` drawn at the bottom left of a frame."""
    from PIL import Image, ImageDraw

    rows = min(height, 20)
    mask = Image.new("L", (width, rows), 0)
    ImageDraw.Draw(mask).text((6, rows - 14), text, fill=255)
    a = np.asarray(mask, dtype=np.float32) / 255.0
    a.flags.writeable = False
    return a


def beside(picture: np.ndarray, image: np.ndarray) -> np.ndarray:
    """(h, w_p + w, 3) uint8: ``picture`` (h, w_p, 3), e.g. the recorded talker at this frame's media time
    (:meth:`assets.video.VideoFrames.shown_at`), left of the rendered ``image`` (h, w, 3), to judge by
    eye whether the mouths move together."""
    if picture.shape[0] != image.shape[0]:
        raise RenderError(f"a picture beside the head must be {image.shape[0]} rows high, got {picture.shape[0]}")
    return np.concatenate([picture, image], axis=1)


@dataclass(frozen=True)
class VideoConfig:
    """fps: video frame rate; crf: H.264 quality (lower is better); preset: x264 speed preset
    (``veryfast`` encodes a 640x480 talking head about 3x faster than ``medium`` at the same crf, the
    file a little larger); ffmpeg: executable name/path."""

    fps: float = 30.0
    crf: int = 20
    preset: str = "medium"
    ffmpeg: str = "ffmpeg"

    def __post_init__(self) -> None:
        presets = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")
        if self.preset not in presets:
            raise RenderError(f"x264 preset must be one of {', '.join(presets)}, got {self.preset!r}")


VIDEO_SUFFIXES = (".mp4", ".mov", ".m4v", ".mkv")  # containers that hold H.264 + AAC (WebM does not)


def check_video_path(out: str | Path) -> Path:
    """``out`` as a Path, or RenderError when its suffix names no container of H.264 + AAC; called before
    any work (rigging a head and rendering take minutes, and ffmpeg only refuses at the end)."""
    p = Path(out)
    if p.suffix.lower() not in VIDEO_SUFFIXES:
        raise RenderError(f"{p}: not a video file name: use {', '.join(VIDEO_SUFFIXES)} (H.264 + AAC)")
    return p


def check_video_size(width: int, height: int) -> None:
    """RenderError unless a video of ``width`` x ``height`` pixels can be encoded; called before any work. H.264 in
    4:2:0 (yuv420p, the chroma format players take) halves the colour planes both ways, so x264 refuses an odd width
    or height, but only when the first frame arrives: after the model, the rig and the render (a whole live session
    for ``view --record``)."""
    if width % 2 or height % 2:
        raise RenderError(
            f"video size {width}x{height}: H.264 (yuv420p) needs an even width and height; "
            f"give e.g. --width {width + width % 2} --height {height + height % 2}"
        )


def write_video(
    frames_params: np.ndarray,
    render_frame,
    out: str | Path,
    *,
    size: tuple[int, int],
    audio: str | Path | None = None,
    png_dir: str | Path | None = None,
    config: VideoConfig = VideoConfig(),
) -> Path:
    """Render one frame per row of frames_params (F, 4) with ``render_frame(params) -> (h, w, 3) uint8``
    (or per element of any sequence render_frame takes, e.g. frame indices) and encode them (plus
    ``audio``) into ``out`` (.mp4); optionally also PNGs into ``png_dir``."""
    from assets.files import make_parent

    out = check_video_path(out)
    check_video_size(*size)
    exe = shutil.which(config.ffmpeg)
    if exe is None:
        raise RenderError(f"{out}: ffmpeg not found ({config.ffmpeg!r}); install it to write videos")
    make_parent(out)
    tmp = out.with_name(f".{out.stem}.tmp{out.suffix}")
    w, h = size
    cmd = [
        exe,
        "-y",
        "-loglevel",
        "error",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-s",
        f"{w}x{h}",
        "-r",
        f"{config.fps}",
        "-i",
        "-",
    ]
    if audio is not None:
        # Each stream named: without -map ffmpeg takes the largest picture among the inputs, so a speech file that is
        # a 1280x720 talking-face video (`render clip.mp4 --beside clip.mp4`) gave its own picture, and stopped
        # reading the frames piped in ("ffmpeg failed (-1)"). The first audio stream, as the reader decodes.
        cmd += ["-i", str(audio), "-map", "0:v:0", "-map", "1:a:0", "-c:a", "aac", "-b:a", "128k", "-shortest"]
    cmd += [
        "-c:v",
        "libx264",
        "-pix_fmt",
        "yuv420p",
        "-crf",
        str(config.crf),
        "-preset",
        config.preset,
        "-movflags",
        "+faststart",
        str(tmp),
    ]
    if png_dir is not None:
        make_parent(Path(png_dir) / "frame_00000.png")
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdin is not None and proc.stderr is not None
    stdin = proc.stdin
    # A writer thread feeds ffmpeg while the next frame renders (a frame is ~1 MB, far beyond the
    # pipe's buffer, so an inline write would wait for the encoder every frame).
    pending: queue.Queue[bytes | None] = queue.Queue(maxsize=4)
    broken: list[BaseException] = []

    def feed() -> None:
        while (chunk := pending.get()) is not None:
            if broken:
                continue  # drain so the renderer never blocks on a dead encoder
            try:
                stdin.write(chunk)
            except (BrokenPipeError, OSError) as exc:
                broken.append(exc)
        try:
            stdin.close()
        except (BrokenPipeError, OSError) as exc:
            broken.append(exc)

    writer = threading.Thread(target=feed, name="ffmpeg-feed", daemon=True)
    writer.start()
    try:
        for k, p in enumerate(frames_params):
            img = render_frame(p)
            pending.put(np.ascontiguousarray(img).tobytes())
            if png_dir is not None:
                from PIL import Image

                Image.fromarray(img).save(Path(png_dir) / f"frame_{k:05d}.png")
            if broken:
                break
    except BaseException:
        pending.put(None)
        writer.join()
        proc.wait()
        tmp.unlink(missing_ok=True)
        raise
    pending.put(None)
    writer.join()
    err = proc.stderr.read().decode(errors="replace")
    rc = proc.wait()
    if rc == 0 and broken:
        rc = -1
    if rc != 0:
        if tmp.exists():
            tmp.unlink()
        raise RenderError(f"{out}: ffmpeg failed ({rc}): {err.strip()[-400:]}")
    os.replace(tmp, out)
    return out
