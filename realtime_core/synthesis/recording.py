"""Text + recording: unit-selection motion blended with the audio-driven model's motion.

When the phones come from a user's recording (forced alignment, or the real audio of an evaluation
sentence), the recording itself says what the text cannot: before speech the mouth opens for an
in-breath whose size varies from sentence to sentence as much as speech does (the largest single
part of unit selection's error, docs/unit_selection.md), and that breath is audible. This module
mixes the audio-driven model's four mouth parameters (the project's live path on the recording)
into the synthesised frames, per frame, with a weight that depends on where the frame lies: the
leading pause (before the first spoken phone), speech, and the trailing pause. The landmark PCA
coefficients follow the parameters through a linear map fitted on the corpus's own frames
(:func:`param_to_coefficient_map`), so landmarks, lip height and width move with the mouth.

This needs a recording: pure text (a synthesiser's phones) has no audio to take the breath from,
and keeps the unit-selection output unchanged. Sans-I/O: the caller runs the audio-driven model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.errors import ConfigError
from realtime_core.synthesis.corpus import FPS, MotionCorpus
from realtime_core.synthesis.visemes import VISEME_ID


@dataclass(frozen=True, kw_only=True)
class RecordingBlend:
    """Weight of the audio-driven motion (0 = unit selection only, 1 = the audio-driven model only)
    in the leading pause, in speech (first to last spoken phone, inner pauses included) and in the
    trailing pause; ``ramp_s``: width of the raised-cosine window that smooths the weight across a
    region boundary (seconds, 0 = a step). Defaults chosen on the GRID s1 val split, leave-one-out
    (docs/unit_selection.md, "Text + recording")."""

    lead: float = 0.7
    speech: float = 0.4
    trail: float = 0.3
    ramp_s: float = 0.2

    def __post_init__(self) -> None:
        for name in ("lead", "speech", "trail"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ConfigError(f"RecordingBlend.{name} must be in [0, 1], got {v!r}")
        if not 0.0 <= self.ramp_s <= 2.0:
            raise ConfigError(f"RecordingBlend.ramp_s must be in [0, 2] s, got {self.ramp_s!r}")


def param_to_coefficient_map(corpus: MotionCorpus) -> np.ndarray:
    """(4, K) least-squares slopes from the four mouth parameters to the landmark PCA coefficients
    over all corpus frames (with an intercept, not returned): a parameter change ``dp`` (n, 4) moves
    the coefficients by ``dp @ map``. Raises ConfigError if the corpus frames do not end in the four
    parameters (:data:`realtime_core.VISUAL_PARAMS`)."""
    k = corpus.n_coefficients
    if tuple(corpus.dim_names[k:]) != VISUAL_PARAMS:
        raise ConfigError(f"the corpus frames must end in the mouth parameters {VISUAL_PARAMS}")
    f = np.asarray(corpus.frames, dtype=np.float64)
    a = np.concatenate([f[:, k:], np.ones((len(f), 1))], axis=1)
    slopes, *_ = np.linalg.lstsq(a, f[:, :k], rcond=None)
    return slopes[: len(VISUAL_PARAMS)]


def speech_span(visemes: np.ndarray, starts_s: np.ndarray, ends_s: np.ndarray) -> tuple[float, float] | None:
    """(onset, offset) seconds of speech in a target (visemes (T,) class ids, starts_s/ends_s (T,)): the first
    spoken (non-pause) phone's start and the last one's end, inner pauses included; None with no spoken phone."""
    spoken = np.flatnonzero(np.asarray(visemes) != VISEME_ID["sil"])
    if spoken.size == 0:
        return None
    return float(starts_s[spoken[0]]), float(ends_s[spoken[-1]])


def region_weights(
    visemes: np.ndarray, starts_s: np.ndarray, ends_s: np.ndarray, n_frames: int, config: RecordingBlend
) -> np.ndarray:
    """(n_frames,) weight of the audio-driven motion at frame k (time k / 30 s) for a gapless target
    (visemes (T,) class ids, starts_s/ends_s (T,)): ``config.lead`` before the first non-pause
    phone, ``config.trail`` from the end of the last one, ``config.speech`` between, smoothed by a
    raised-cosine window of ``config.ramp_s``. A target with no spoken phone is all leading pause."""
    t = np.arange(n_frames) / FPS
    span = speech_span(visemes, starts_s, ends_s)
    w = np.full(n_frames, float(config.lead))
    if span is not None:
        onset, offset = span
        w[t >= onset] = config.speech
        w[t >= offset] = config.trail
    half = int(round(config.ramp_s * FPS / 2))
    if half > 0 and n_frames > 1:
        kernel = np.hanning(2 * half + 3)[1:-1]  # 2 half + 1 strictly positive taps
        w = np.convolve(np.pad(w, half, mode="edge"), kernel / kernel.sum(), mode="valid")
    return w


def blend_recording(
    frames: np.ndarray, audio_params: np.ndarray, weights: np.ndarray, coefficient_map: np.ndarray
) -> np.ndarray:
    """Synthesised ``frames`` (n, K + 4) with the audio-driven ``audio_params`` (m, 4) mixed in by
    ``weights`` (n,): the parameters become ``(1 - w) p + w a`` and the K coefficients move by the
    same parameter change through ``coefficient_map`` (4, K). ``audio_params`` are at 30 fps from
    frame 0; if shorter than the motion their last frame is held, if longer they are cut."""
    frames = np.asarray(frames, dtype=np.float64)
    a = np.asarray(audio_params, dtype=np.float64)
    n, d = frames.shape
    p = len(VISUAL_PARAMS)
    k = d - p
    if a.ndim != 2 or a.shape[1] != p or len(a) == 0:
        raise ConfigError(f"audio_params must be (m >= 1, {p}), got {a.shape}")
    if np.shape(coefficient_map) != (p, k) or np.shape(weights) != (n,):
        raise ConfigError(f"coefficient_map must be ({p}, {k}) and weights ({n},)")
    if len(a) < n:
        a = np.concatenate([a, np.repeat(a[-1:], n - len(a), axis=0)])
    dp = np.asarray(weights, dtype=np.float64)[:, None] * (a[:n] - frames[:, k:])
    out = frames.copy()
    out[:, k:] += dp
    out[:, :k] += dp @ coefficient_map
    return out
