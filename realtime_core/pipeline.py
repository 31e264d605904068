"""Speech samples -> mouth parameters, streaming (live) and whole-utterance (offline).

:class:`SpeechToParams` chains the front end (MFCC -> CMVN -> context) and the model's streaming
visual mapper (:class:`realtime_core.mapping.VisualMapper`: the HMM inverter of an
:class:`AvModel`, or the GMM-selected MLP bank of an :class:`MlpSpeechModel`). ``push(samples)`` returns the parameter rows now final, ``flush()`` the rest;
row ``k`` is video frame ``k`` (time ``k / 30`` s). The first row of an utterance appears
once the audio reaches frame ``tc + lag`` plus one analysis window: the algorithmic
delay is ``(tc + lag) / fps`` seconds plus the window.

:func:`speech_to_params` runs the same objects over a whole utterance, so offline results
equal what a live session produces frame for frame; ``mode="batch"`` uses batch HMMI
(eq. 7 EM) instead.
"""

from __future__ import annotations

import numpy as np

from realtime_core.avmodel import AvModel
from realtime_core.errors import ConfigError, InvalidAudioError
from realtime_core.features.mfcc import as_float_samples
from realtime_core.inversion import HmmiConfig, StreamConfig, hmm_inversion
from realtime_core.mapping import SpeechModel


class SpeechToParams:
    """``push(samples (n,) at model.sample_rate_hz) -> (k, n_visual) float64``; ``flush()``.

    model: any :class:`realtime_core.mapping.SpeechModel`; ``stream`` sets the HMM inverter's lag,
    dtype and likelihood scale (an MLP model takes its lag and dtype)."""

    def __init__(self, model: SpeechModel, *, stream: StreamConfig = StreamConfig()) -> None:
        self.model = model
        self._fe = model.front_end()
        if isinstance(model, AvModel):
            self._inv = model.inverter(stream)
        else:
            self._inv = model.visual_mapper(lag=stream.lag, dtype=stream.dtype)
        self.frames_out = 0

    @property
    def delay_frames(self) -> int:
        """Frames of lookahead between the newest audio frame and the newest output."""
        return self.model.frontend.tc + self._inv.lag_frames

    def reset(self) -> None:
        self._fe.reset()
        self._inv.reset()
        self.frames_out = 0

    def push(self, samples: np.ndarray) -> np.ndarray:
        out = self._inv.push(self._fe.push(samples))
        self.frames_out += len(out)
        return out

    def flush(self) -> np.ndarray:
        out = np.concatenate([self._inv.push(self._fe.flush()), self._inv.flush()])
        self.frames_out += len(out)
        return out


def speech_to_params(
    model: SpeechModel,
    samples: np.ndarray,
    *,
    mode: str = "stream",
    stream: StreamConfig = StreamConfig(),
    hmmi: HmmiConfig = HmmiConfig(),
) -> np.ndarray:
    """Whole utterance: ``(n,)`` samples at ``model.sample_rate_hz`` -> ``(n_frames, n_visual)``.

    mode "stream" is exactly the live path; "batch" is batch HMMI (eq. 7 EM, HMM models only).
    """
    if mode not in ("stream", "batch"):
        raise ConfigError(f"mode must be 'stream' or 'batch', got {mode!r}")
    if mode == "batch" and not isinstance(model, AvModel):
        raise ConfigError("mode 'batch' (batch HMMI) needs an HMM model")
    x = as_float_samples(samples)
    if x.size < model.frontend.mfcc.window_len:
        raise InvalidAudioError(
            f"audio too short: {x.size} samples, need at least {model.frontend.mfcc.window_len} "
            f"({1000 * model.frontend.mfcc.window_len / model.sample_rate_hz:.0f} ms)"
        )
    if mode == "stream":
        p = SpeechToParams(model, stream=stream)
        return np.concatenate([p.push(x), p.flush()])
    fe = model.front_end()
    oa = np.concatenate([fe.push(x), fe.flush()])
    return hmm_inversion(model.form, oa, config=hmmi).visual
