"""The face at rest before and after synthesised speech: the leading and trailing pauses eased to the rest pose.

Unit selection fills a target's leading pause with a recorded GRID pause, and the talker there is
often mid in-breath with parted lips (docs/unit_selection.md, "The leading pause is not predictable
from text and timings"): "Hello, how are you today?" started at mouth_open 0.156 IOD over silence.
Synthesised speech has no in-breath, so a viewer expects the lips together before the first word
and after the last. :func:`ease_to_rest` pulls every frame before the first spoken phone and after
the last one to the rest pose (the whole frame vector: landmark coefficients and mouth parameters),
with a smooth ramp of ``RestPauses.ramp_s`` (:func:`realtime_core.synthesis.search.crossfade`, the junctions'
blend) that reaches the recorded motion exactly at the
first spoken phone's start (and leaves it at the last one's end): speech itself, inner pauses
included, is unchanged. Only for phones of a synthesiser; a real recording's in-breath is real
(:mod:`realtime_core.synthesis.recording`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.synthesis.corpus import FPS
from realtime_core.synthesis.recording import speech_span
from realtime_core.synthesis.search import crossfade


@dataclass(frozen=True, kw_only=True)
class RestPauses:
    """ramp_s: seconds over which the face leaves the rest pose before the first spoken phone (and
    comes back to it after the last one), the junctions' smoothstep blend; shortened to the pause when the pause is
    shorter, so the first and last frames are at rest whenever there is a pause at all. The default
    0.2 s (6 frames): the steepest step of the ramp is 1.5 / 6 = 0.25 of the distance between the rest
    pose and speech's first frame, under the speech's own largest frame-to-frame change
    (docs/unit_selection.md, "The face at rest before and after synthesised speech")."""

    ramp_s: float = 0.2

    def __post_init__(self) -> None:
        if not 1.0 / FPS <= self.ramp_s <= 1.0:
            raise ConfigError(f"RestPauses.ramp_s must be in [{1 / FPS:.3f}, 1] s, got {self.ramp_s!r}")


def rest_weights(
    visemes: np.ndarray,
    starts_s: np.ndarray,
    ends_s: np.ndarray,
    n_frames: int,
    config: RestPauses = RestPauses(),
    fps: float = FPS,
) -> np.ndarray:
    """(n_frames,) weight of the rest pose at frame k (time k / fps) for a gapless target (visemes (T,)
    class ids, starts_s/ends_s (T,) seconds): 1 in the leading and trailing pauses, 0 from the first
    spoken phone's start to the last one's end, the smoothstep blend over ``config.ramp_s`` (or the whole
    pause when it is shorter) into and out of speech. A target with no spoken phone is all rest."""
    t = np.arange(n_frames) / fps
    span = speech_span(visemes, starts_s, ends_s)
    if span is None:
        return np.ones(n_frames)
    onset, offset = span
    w = np.zeros(n_frames)
    lead = min(config.ramp_s, onset)
    if lead > 0:
        # 1 up to onset - lead, then down to 0 at the onset
        w = np.where(t < onset, crossfade((onset - t) / lead), w)
    last = (n_frames - 1) / fps
    trail = min(config.ramp_s, last - offset)
    if trail > 0:
        w = np.where(t > offset, crossfade((t - offset) / trail), w)
    return w


def ease_to_rest(
    frames: np.ndarray,
    visemes: np.ndarray,
    starts_s: np.ndarray,
    ends_s: np.ndarray,
    rest: np.ndarray,
    config: RestPauses = RestPauses(),
    fps: float = FPS,
) -> np.ndarray:
    """frames (n, D) at ``k / fps`` blended towards ``rest`` (D,) by :func:`rest_weights`. Returns a new array."""
    frames = np.asarray(frames, np.float64)
    rest = np.asarray(rest, np.float64)
    if rest.shape != frames.shape[1:]:
        raise ConfigError(f"rest must be {frames.shape[1:]} like a frame, got {rest.shape}")
    w = rest_weights(visemes, starts_s, ends_s, len(frames), config, fps)
    return frames + w[:, None] * (rest - frames)
