"""Speech samples -> mouth parameters, streaming (live) and whole-utterance (offline).

:class:`SpeechToParams` chains the front end (MFCC -> CMVN -> context) and the model's streaming
visual mapper (:class:`realtime_core.mapping.VisualMapper`: the HMM inverter of an
:class:`AvModel`, or the GMM-selected MLP bank of an :class:`MlpSpeechModel`). ``push(samples)``
returns the parameter rows now final, ``flush()`` the rest; row ``k`` is video frame ``k`` (time ``k / 30`` s).
The first row of an utterance appears once the audio reaches frame ``tc + lag`` plus one analysis
window: the algorithmic delay is ``(tc + lag) / fps`` seconds plus the window
(:meth:`realtime_core.features.FrontEndConfig.algorithmic_delay_ms`).

:func:`speech_to_params` runs the same objects over a whole utterance, so offline results
equal what a live session produces frame for frame; ``mode="batch"`` uses batch HMMI
(eq. 7 EM) instead.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, cast

import numpy as np

from realtime_core.avmodel import AvModel
from realtime_core.errors import ConfigError, InvalidAudioError
from realtime_core.features.gain import InputGainConfig
from realtime_core.features.mfcc import as_float_samples
from realtime_core.features.noisegate import NoiseGate, NoiseGateConfig
from realtime_core.features.resample import StreamingResampler, resample_audio
from realtime_core.inversion import HmmiConfig, StreamConfig, hmm_inversion
from realtime_core.mapping import SpeechModel, VisualMapper
from realtime_core.mapping.model import MlpSpeechModel

StageObserver = Callable[[str], None]
"""Called with a stage name (``"resample"``, ``"features"``, ``"inversion"``) right after that stage
ran on a push: the caller reads its own clock between calls (the core reads none)."""

STAGES = ("resample", "features", "inversion")


class SpeechToParams:
    """The live chain: ``push(samples (n,) at rate_hz) -> (k, n_visual) float64``; ``flush()``.

    Samples at any ``rate_hz`` (default: the model's rate) go through a :class:`StreamingResampler`
    (bit-identical to whole-signal ``resample_poly`` for any chunking), the model's front end
    (MFCC -> CMVN -> context) and the model's streaming visual mapper. ``observer`` (optional) is told
    after each stage of every push, for per-stage timings.

    model: any :class:`realtime_core.mapping.SpeechModel`; ``stream`` sets the HMM inverter's lag,
    dtype and likelihood scale (an MLP model takes its lag and dtype), and the per-frame kernels of
    the front end and the inverter (``stream.kernel``: compiled "numba" or the "numpy" reference).
    noise_gate: the output noise gate (:mod:`realtime_core.features.noisegate`: a room's steady noise alone
    fades the mouth to the rest pose; its lookahead is the front end's context, no added delay), or None for
    the mapper's rows as they are.
    """

    def __init__(
        self,
        model: SpeechModel,
        *,
        rate_hz: int | None = None,
        stream: StreamConfig = StreamConfig(),
        observer: StageObserver | None = None,
        noise_gate: NoiseGateConfig | None = NoiseGateConfig(),
    ) -> None:
        self.model = model
        self.rate_hz = int(rate_hz) if rate_hz is not None else model.sample_rate_hz
        self._resampler = (
            StreamingResampler(self.rate_hz, model.sample_rate_hz) if self.rate_hz != model.sample_rate_hz else None
        )
        self._fe = model.front_end(kernel=stream.kernel)
        self._inv: VisualMapper
        if isinstance(model, AvModel):
            self._inv = model.inverter(stream)
        else:
            self._inv = model.visual_mapper(lag=stream.lag, dtype=stream.dtype)
        self._gate = NoiseGate(noise_gate, lookahead=model.frontend.tc) if noise_gate is not None else None
        # The MUPs a gated row's expression is computed from are faded with it (towards the silent face's).
        self._rest_mups = (
            model.rest_mups(stream.dtype)
            if self._gate is not None and isinstance(model, MlpSpeechModel) and model.expressions is not None
            else None
        )
        self._observe: StageObserver = observer if observer is not None else _ignore
        self.frames_out = 0
        self.last_mups: np.ndarray | None = None
        """The MU parameters ``(j, A0)`` of the rows the last push/flush returned, when the model's mapper
        emits them (an MLP mapper with expression stages); None otherwise."""
        self.model_audio: np.ndarray = np.zeros(0)
        """The model-rate samples (n,) float64 the last push/flush fed to the front end (what a live
        session relays to listeners: the audio the model heard, in step with the frames)."""

    @property
    def delay_frames(self) -> int:
        """Frames of lookahead between the newest audio frame and the newest output."""
        return self.model.frontend.tc + self._inv.lag_frames

    @property
    def algorithmic_delay_ms(self) -> float:
        """The model's algorithmic delay at this chain's lag, plus the resampler's lookahead when the
        input is not at the model rate (under 1 ms)."""
        extra = 0.0 if self._resampler is None else 1e3 * self._resampler.delay_samples_in / self.rate_hz
        return self.model.frontend.algorithmic_delay_ms(self._inv.lag_frames) + extra

    def reset(self) -> None:
        if self._resampler is not None:
            self._resampler.reset()
        self._fe.reset()
        self._inv.reset()
        if self._gate is not None:
            self._gate.reset()
        self.frames_out = 0

    def _with_levels(self, feats: np.ndarray) -> np.ndarray:
        """``feats``, the rows the front end has just given; their frames' levels go to the noise gate."""
        if self._gate is not None:
            self._gate.push_levels(self._fe.last_level_db)
        return feats

    def _gated(self, out: np.ndarray) -> np.ndarray:
        """The rows ``out`` (and :attr:`last_mups`, theirs) through the output noise gate, when there is one."""
        if self._gate is None:
            return out
        out = self._gate.apply(out)
        if self.last_mups is not None and self._rest_mups is not None:
            self.last_mups = self._gate.fade(self.last_mups, self._rest_mups)
        return out

    def push(self, samples: np.ndarray) -> np.ndarray:
        """samples: (n,) float32/float64 in [-1, 1] or int16, at ``rate_hz``."""
        x = as_float_samples(samples)
        if self._resampler is not None:
            x = self._resampler.push(x)
        self.model_audio = x
        self._observe("resample")
        feats = self._with_levels(self._fe.push(x))
        self._observe("features")
        out = self._inv.push(feats)
        self.last_mups = getattr(self._inv, "last_mups", None)
        out = self._gated(out)
        self._observe("inversion")
        self.frames_out += len(out)
        return out

    def flush(self) -> np.ndarray:
        self.model_audio = self._resampler.flush() if self._resampler is not None else np.zeros(0)
        self._observe("resample")
        tail = self._with_levels(self._fe.push(self.model_audio)) if self.model_audio.size else np.zeros((0, 0))
        feats = self._with_levels(self._fe.flush())
        feats = np.concatenate([tail, feats]) if len(tail) else feats
        self._observe("features")
        head = self._inv.push(feats)
        mups = getattr(self._inv, "last_mups", None)
        out = np.concatenate([head, self._inv.flush()])
        tail_mups = getattr(self._inv, "last_mups", None)
        self.last_mups = None if mups is None or tail_mups is None else np.concatenate([mups, tail_mups])
        out = self._gated(out)
        self._observe("inversion")
        self.frames_out += len(out)
        return out


def with_auto_gain(model: SpeechModel, config: InputGainConfig | None = None) -> SpeechModel:
    """``model`` whose front end first brings its input to the training speech level (the causal gain stage,
    :class:`realtime_core.features.gain.InputGainConfig`, default settings when ``config`` is None): a quiet take
    moves the mouth as a loud one once the speech level has been heard (a few seconds). Both mappers' models are
    frozen dataclasses with a ``frontend`` (the SpeechModel protocol names no fields, hence the cast)."""
    from dataclasses import replace

    gain = InputGainConfig() if config is None else config
    gained: Any = replace(cast(Any, model), frontend=replace(model.frontend, input_gain=gain))
    return cast(SpeechModel, gained)


def _ignore(stage: str) -> None:
    """The default observer: timings not wanted."""


def speech_to_params_and_mups(
    model: SpeechModel,
    samples: np.ndarray,
    rate_hz: int | None = None,
    *,
    noise_gate: NoiseGateConfig | None = NoiseGateConfig(),
) -> tuple[np.ndarray, np.ndarray | None]:
    """The live path over a whole utterance, keeping the mapper's MU parameters: ``(params (n, Dv),
    mups (n, A0) or None)`` (None when the model's mapper emits none)."""
    x = as_float_samples(samples)
    if rate_hz is not None and int(rate_hz) != model.sample_rate_hz:
        x = resample_audio(x, int(rate_hz), model.sample_rate_hz)
    return _run_blocks(SpeechToParams(model, noise_gate=noise_gate), x)


PUSH_BLOCK_S = 10.0
"""Seconds of audio per push when a whole utterance runs through the live chain. One push of a whole
file framed all of it at once (the MFCC frames and spectra of every hop): 610 MB of numpy arrays at
the peak for a 10-minute file, growing with its length; blocks keep that bounded (41 MB) and give the
same rows bit for bit (the chain is chunking-invariant)."""


def _run_blocks(p: SpeechToParams, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """``x (n,)`` model-rate samples through ``p`` in :data:`PUSH_BLOCK_S` blocks, then its flush:
    ``(params (F, Dv), mups (F, A0) or None)``."""
    step = max(1, int(PUSH_BLOCK_S * p.model.sample_rate_hz))
    rows: list[np.ndarray] = []
    mups: list[np.ndarray] | None = []
    for i in [*range(0, len(x), step), -1]:
        rows.append(p.push(x[i : i + step]) if i >= 0 else p.flush())
        if mups is not None and p.last_mups is not None:
            mups.append(p.last_mups)
        else:
            mups = None
    return np.concatenate(rows), None if mups is None else np.concatenate(mups)


def speech_to_params(
    model: SpeechModel,
    samples: np.ndarray,
    rate_hz: int | None = None,
    *,
    mode: str = "stream",
    stream: StreamConfig = StreamConfig(),
    hmmi: HmmiConfig = HmmiConfig(),
    noise_gate: NoiseGateConfig | None = NoiseGateConfig(),
) -> np.ndarray:
    """Whole utterance: ``(n,)`` samples at ``rate_hz`` (default the model's) -> ``(n_frames, n_visual)``.

    mode "stream" is exactly the live path (the same :class:`SpeechToParams` objects, with the model's
    readout and output stage); "batch" is batch HMMI (eq. 7 EM, HMM models only) on the same resampled
    audio, then the output stage: the paper's offline estimator, without the learned readout (which is
    fitted on the live path's filtered posteriors, not HMMI's) and without the noise gate.
    noise_gate: the live path's output noise gate (:class:`SpeechToParams`), None for none.
    """
    if mode not in ("stream", "batch"):
        raise ConfigError(f"mode must be 'stream' or 'batch', got {mode!r}")
    if mode == "batch" and not isinstance(model, AvModel):
        raise ConfigError("mode 'batch' (batch HMMI) needs an HMM model")
    x = as_float_samples(samples)
    if rate_hz is not None and int(rate_hz) != model.sample_rate_hz:
        x = resample_audio(x, int(rate_hz), model.sample_rate_hz)
    if x.size < model.frontend.mfcc.window_len:
        raise InvalidAudioError(
            f"audio too short: {1000 * x.size / model.sample_rate_hz:.0f} ms, need at least "
            f"{1000 * model.frontend.mfcc.window_len / model.sample_rate_hz:.0f} ms "
            f"({x.size} < {model.frontend.mfcc.window_len} samples at {model.sample_rate_hz} Hz)"
        )
    if mode == "stream":
        return _run_blocks(SpeechToParams(model, stream=stream, noise_gate=noise_gate), x)[0]
    assert isinstance(model, AvModel)  # refused above otherwise; narrows the type for what follows
    fe = model.front_end()
    oa = np.concatenate([fe.push(x), fe.flush()])
    return model.output_stage(hmm_inversion(model.form, oa, config=hmmi).visual)
