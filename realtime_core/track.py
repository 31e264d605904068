"""A track: named channels sampled on a regular frame grid (the four mouth parameters over time,
blendshape weights, ...). The one value type every codec, exporter, renderer and corpus shares.

It lives in the core, not with its codecs (``assets.tracks``), because it is pure data with no I/O:
the core defines what a parameter track is (``VISUAL_PARAMS`` at 30 fps) and every layer above,
from the asset codecs to the exporters and the corpus, can build and read one without importing
sideways. :func:`frames_from_samples` puts irregularly timed samples onto a frame grid (the render
side's "any rate in" CSVs); it is named apart from the audio resamplers on purpose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.errors import ConfigError

DEFAULT_FPS = 30.0
"""The video frame rate of every model output and corpus track (frames/s)."""


@dataclass(frozen=True, kw_only=True)
class Track:
    """values: ``(n_frames, n_channels) float64`` (a private read-only copy), row k at media time
    ``start_s + k / fps`` seconds; names: one per channel (default the four mouth parameters, in
    IOD units); fps: frames per second (> 0); start_s: media time of row 0 (s, >= 0)."""

    values: np.ndarray
    names: tuple[str, ...] = VISUAL_PARAMS
    fps: float = DEFAULT_FPS
    start_s: float = 0.0

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.names)
        v = np.array(self.values, dtype=np.float64)  # a private copy: the track is immutable
        if v.ndim != 2 or v.shape[1] != len(names):
            raise ConfigError(f"track values must be (n_frames, {len(names)}) for names {names}, got shape {v.shape}")
        if len(set(names)) != len(names):
            raise ConfigError(f"track channel names must be distinct, got {names}")
        if not np.all(np.isfinite(v)):
            raise ConfigError("track values contain NaN or infinite values")
        if (
            isinstance(self.fps, bool)
            or not isinstance(self.fps, (int, float, np.number))
            or not (np.isfinite(self.fps) and self.fps > 0)
        ):
            raise ConfigError(f"track fps must be a positive number, got {self.fps!r}")
        if not (isinstance(self.start_s, (int, float, np.number)) and np.isfinite(self.start_s) and self.start_s >= 0):
            raise ConfigError(f"track start_s must be a finite time >= 0 s, got {self.start_s!r}")
        v.setflags(write=False)
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "fps", float(self.fps))
        object.__setattr__(self, "start_s", float(self.start_s))

    @property
    def n_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def n_channels(self) -> int:
        return int(self.values.shape[1])

    @property
    def duration_s(self) -> float:
        """Seconds covered: n_frames / fps (the last frame lasts one frame period)."""
        return self.n_frames / self.fps

    def times(self) -> np.ndarray:
        """``(n_frames,) float64`` seconds: the media time of each row."""
        return self.start_s + np.arange(self.n_frames) / self.fps

    def at_fps(self, fps: float) -> Track:
        """The track on the frame grid ``k / fps`` (from 0 s) covering as long as it does: every frame that starts
        before its end (``start_s + duration_s``, its last row lasting one frame period), linearly interpolated
        between rows and each channel held after the last. A video of it then lasts as long as the speech its rows
        cover: put on the grid through the last row's time instead (:func:`frames_from_samples`'s default), 93
        frames at 30 fps (3.1 s, for 3.095 s of speech) became 92 at 29.97 (3.0697 s), and `render --fps 29.97`'s
        video ended 25 ms before the speech, which ffmpeg's ``-shortest`` then cut there."""
        if fps == self.fps and self.start_s == 0:
            return self
        return frames_from_samples(
            self.times(), self.values, fps, names=self.names, until_s=self.start_s + self.duration_s
        )

    def channel(self, name: str) -> np.ndarray:
        """``(n_frames,)`` values of channel ``name``."""
        try:
            return self.values[:, self.names.index(name)]
        except ValueError:
            raise ConfigError(f"track has no channel {name!r}; it has {self.names}") from None


def frames_from_samples(
    times_s: np.ndarray,
    values: np.ndarray,
    fps: float,
    *,
    names: tuple[str, ...] = VISUAL_PARAMS,
    until_s: float | None = None,
) -> Track:
    """Samples at strictly increasing ``times_s`` ``(T,)`` seconds with ``values`` ``(T, C)`` -> the
    track at frames ``k / fps`` for ``k < floor(times_s[-1] * fps + 1e-4) + 1``, linearly interpolated per
    channel (held constant before the first sample and after the last). Starts at 0 s whatever the first time.
    ``until_s``: instead, every frame that starts before this time (s; one starting within 1e-4 frame of it is not
    added): ``ceil(until_s * fps - 1e-4)`` frames, so that they cover as long (:meth:`Track.at_fps`)."""
    t = np.asarray(times_s, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or v.ndim != 2 or len(t) != len(v) or len(t) == 0:
        raise ConfigError(f"need times (T,) and values (T, C) with T >= 1, got {t.shape} and {v.shape}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ConfigError("sample times must be finite and strictly increasing")
    if not fps > 0:
        raise ConfigError(f"fps must be > 0, got {fps}")
    # A sample within 1e-4 of a frame before its time is that frame's: a track file's times are rounded
    # (facecast's CSV writes 1/30 s as 0.033333, 1.5e-5 frames early), and a strict floor dropped the last frame.
    if until_s is None:
        n = max(int(np.floor(t[-1] * fps + 1e-4)) + 1, 0)
    else:
        n = max(int(np.ceil(until_s * fps - 1e-4)), 1)
    ft = np.arange(n) / fps
    out = np.zeros((n, v.shape[1]))
    for j in range(v.shape[1]):
        out[:, j] = np.interp(ft, t, v[:, j])
    return Track(values=out, names=names, fps=fps)
