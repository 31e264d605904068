"""Incremental MFCCs at the video frame rate (paper Sec. 3 and 6.3).

Theory of operation
-------------------
Audio is cut into frames at exactly ``frame_rate_hz`` (30 fps by default) even when
``sample_rate_hz / frame_rate_hz`` is not an integer: frame ``k`` starts at sample
``floor(k * sample_rate_hz / frame_rate_hz)`` (computed in exact rational arithmetic), so
frames never drift against the video clock. Each frame is ``window_len`` samples long
(about two hops), pre-emphasised, Hamming-windowed, zero-padded to ``n_fft``, and turned
into ``n_ceps`` cepstral coefficients c1..c_n (the paper's "first eleven non-DC
coefficients") through the power spectrum, a triangular mel filterbank, log and an
orthonormal DCT-II. The filterbank uses the classic HTK/python_speech_features bin
placement so results can be checked against that independent library.

There is no centre padding: a frame is emitted by :meth:`MfccStream.push` once all of its
samples have arrived. :meth:`MfccStream.flush` ends the utterance and emits the frames
that start before the end of the audio, zero-padded, so an utterance of duration ``d``
seconds gives ``ceil(d * frame_rate_hz)`` frames, one per video frame.

Pre-emphasis runs over the continuous stream (``x[-1] = 0``), so chunking never changes
the output beyond rounding: the frames of one push go through one batched FFT, whose last bits
depend on the batch (c0 up to 2e-14 apart, whole input against sample by sample; the tests allow 1e-12).
Stages after it that must be bit-identical for any chunking read it at float32 (the inverter, the noise gate).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from fractions import Fraction
from typing import NamedTuple

import numpy as np
import scipy.fft

from realtime_core.errors import ConfigError, InvalidAudioError, StreamStateError

_MIN_RATE_HZ = 8000
_MAX_RATE_HZ = 48000


def hz_to_mel(hz: np.ndarray | float) -> np.ndarray | float:
    """HTK mel scale. ``hz`` in Hz (any shape) -> mels (same shape)."""
    return 2595.0 * np.log10(1.0 + np.asarray(hz) / 700.0)


def mel_to_hz(mel: np.ndarray | float) -> np.ndarray | float:
    """Inverse of :func:`hz_to_mel`."""
    return 700.0 * (10.0 ** (np.asarray(mel) / 2595.0) - 1.0)


def mel_filterbank(*, sample_rate_hz: int, n_fft: int, n_mels: int, fmin_hz: float, fmax_hz: float) -> np.ndarray:
    """Triangular mel filterbank, ``(n_fft // 2 + 1, n_mels) float64``.

    Filter edges sit on FFT bins ``floor((n_fft + 1) * f / sample_rate_hz)`` with ``f``
    equally spaced in mel between ``fmin_hz`` and ``fmax_hz`` (HTK-style placement, the
    same as python_speech_features, so the two agree to rounding).
    """
    mels = np.linspace(hz_to_mel(fmin_hz), hz_to_mel(fmax_hz), n_mels + 2)
    bins = np.floor((n_fft + 1) * mel_to_hz(mels) / sample_rate_hz).astype(int)
    fb = np.zeros((n_mels, n_fft // 2 + 1))
    for m in range(n_mels):
        lo, mid, hi = bins[m], bins[m + 1], bins[m + 2]
        for k in range(lo, mid):
            fb[m, k] = (k - lo) / max(mid - lo, 1)
        for k in range(mid, hi):
            fb[m, k] = (hi - k) / max(hi - mid, 1)
    return fb.T.copy()


def vtlp_warp_hz(freqs_hz: np.ndarray, warp: float, nyquist_hz: float) -> np.ndarray:
    """The piecewise-linear vocal-tract-length warp of frequencies (Jaitly & Hinton 2013; Kaldi's VTLN
    form): ``f -> warp * f`` up to ``f0 = 0.8 * nyquist * min(1, 1 / warp)``, then the straight line to
    ``(nyquist, nyquist)``, so the band edge stays put. ``freqs_hz`` any shape; returns the same shape."""
    f = np.asarray(freqs_hz, dtype=np.float64)
    f0 = 0.8 * nyquist_hz * min(1.0, 1.0 / warp)
    return np.where(f <= f0, warp * f, warp * f0 + (nyquist_hz - warp * f0) * (f - f0) / (nyquist_hz - f0))


def warp_filterbank(fbank: np.ndarray, *, sample_rate_hz: int, n_fft: int, warp: float) -> np.ndarray:
    """A filterbank ``(n_fft // 2 + 1, n_mels)`` that reads the spectrum as if its frequencies were scaled
    by ``warp`` (:func:`vtlp_warp_hz`): a formant at ``f`` lands in the filters of ``warp * f``, so
    ``warp`` > 1 makes a voice look like a shorter vocal tract's. Each filter is resampled linearly."""
    f = np.arange(fbank.shape[0]) * sample_rate_hz / n_fft
    w = vtlp_warp_hz(f, warp, sample_rate_hz / 2)
    return np.stack([np.interp(w, f, fbank[:, m]) for m in range(fbank.shape[1])], axis=1)


@dataclass(frozen=True, kw_only=True)
class MfccConfig:
    """Settings of the MFCC front end. Validated once at construction.

    sample_rate_hz: input rate, 8000-48000 Hz (integer).
    frame_rate_hz: output rows per second (the video rate); 30 by default.
    window_hops: analysis window length in hops (about two hops long by default).
    n_ceps: number of cepstral coefficients c1..c_n returned (11 in the paper).
    include_c0: also return c0 first (then rows have n_ceps + 1 columns).
    n_mels: mel filters; fmin_hz/fmax_hz: filterbank range (fmax None -> Nyquist).
    preemphasis: first-order pre-emphasis coefficient (0 disables).
    lifter: sinusoidal cepstral lifter L (0 disables), as in HTK.
    energy_floor: power floor before the log (input scaled to [-1, 1]).
    warp: frequency warp of the filterbank (:func:`warp_filterbank`, 0.8-1.25; 1 = none): training
        uses it to make copies of a voice with a longer or shorter vocal tract (VTLP, issue 10).
    """

    sample_rate_hz: int = 16000
    frame_rate_hz: int = 30
    window_hops: float = 2.0
    n_ceps: int = 11
    include_c0: bool = False
    n_mels: int = 26
    fmin_hz: float = 0.0
    fmax_hz: float | None = None
    preemphasis: float = 0.97
    lifter: float = 0.0
    energy_floor: float = 1e-10
    warp: float = 1.0
    # Derived values, computed once.
    window_len: int = field(init=False)
    n_fft: int = field(init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.sample_rate_hz, (int, np.integer)) or not (
            _MIN_RATE_HZ <= self.sample_rate_hz <= _MAX_RATE_HZ
        ):
            raise ConfigError(
                f"sample_rate_hz must be an integer in {_MIN_RATE_HZ}..{_MAX_RATE_HZ}, got {self.sample_rate_hz!r}"
            )
        if not isinstance(self.frame_rate_hz, (int, np.integer)) or not 1 <= self.frame_rate_hz <= 200:
            raise ConfigError(f"frame_rate_hz must be an integer in 1..200, got {self.frame_rate_hz!r}")
        if not 1.0 <= self.window_hops <= 4.0:
            raise ConfigError(f"window_hops must be in [1, 4], got {self.window_hops}")
        if not 1 <= self.n_ceps < self.n_mels:
            raise ConfigError(f"n_ceps must be in 1..n_mels-1 ({self.n_mels - 1}), got {self.n_ceps}")
        fmax = self.sample_rate_hz / 2 if self.fmax_hz is None else self.fmax_hz
        if not 0 <= self.fmin_hz < fmax <= self.sample_rate_hz / 2:
            raise ConfigError(f"need 0 <= fmin_hz < fmax_hz <= Nyquist, got {self.fmin_hz}, {fmax}")
        if not 0.0 <= self.preemphasis < 1.0:
            raise ConfigError(f"preemphasis must be in [0, 1), got {self.preemphasis}")
        if self.lifter < 0 or self.energy_floor <= 0:
            raise ConfigError("lifter must be >= 0 and energy_floor > 0")
        if not 0.8 <= self.warp <= 1.25:
            raise ConfigError(f"warp must be in [0.8, 1.25], got {self.warp}")
        win = int(round(self.window_hops * self.sample_rate_hz / self.frame_rate_hz))
        object.__setattr__(self, "window_len", win)
        object.__setattr__(self, "n_fft", 1 << (win - 1).bit_length())

    @property
    def hop(self) -> Fraction:
        """Exact hop in samples (may be fractional: 16 kHz -> 1600/3)."""
        return Fraction(int(self.sample_rate_hz), int(self.frame_rate_hz))

    @property
    def n_outputs(self) -> int:
        """Columns per output row."""
        return self.n_ceps + (1 if self.include_c0 else 0)

    def frame_start(self, k: int) -> int:
        """First sample of frame ``k``: ``floor(k * sample_rate_hz / frame_rate_hz)``."""
        return (k * int(self.sample_rate_hz)) // int(self.frame_rate_hz)

    def n_frames_for(self, n_samples: int) -> int:
        """Frames an utterance of ``n_samples`` yields after flush: ``ceil(n * fps / rate)``."""
        return -((-n_samples * int(self.frame_rate_hz)) // int(self.sample_rate_hz))


def as_float_samples(samples: np.ndarray, *, what: str = "samples") -> np.ndarray:
    """Validate a mono block and return it as float64 in [-1, 1] scale.

    ``samples``: ``(n,)`` float32/float64 (already scaled to [-1, 1]) or int16 (scaled by
    1/32768). Raises :class:`InvalidAudioError` naming the problem otherwise.
    """
    arr = np.asarray(samples)
    if arr.ndim != 1:
        raise InvalidAudioError(f"{what} must be a 1-D mono array, got shape {arr.shape}")
    if arr.dtype == np.int16:
        return arr.astype(np.float64) / 32768.0
    if arr.dtype not in (np.float32, np.float64):
        raise InvalidAudioError(f"{what} must be float32, float64 or int16, got dtype {arr.dtype}")
    out = arr.astype(np.float64, copy=False)
    # The sum is non-finite iff some sample is NaN/inf (finite audio cannot overflow it):
    # one reduction instead of a boolean array per block on the live path.
    if not np.isfinite(np.add.reduce(out)) and not np.all(np.isfinite(out)):
        bad = int(np.flatnonzero(~np.isfinite(out))[0])
        raise InvalidAudioError(f"{what} contain NaN or inf (first at index {bad})")
    return out


class _Tables(NamedTuple):
    """The constant tables of one :class:`MfccConfig` (read-only, shared by every stream of it)."""

    fbank: np.ndarray  # (n_fft // 2 + 1, n_mels) float64
    window: np.ndarray  # (window_len,) float64 Hamming
    dct: np.ndarray  # (n_mels, n_outputs) float64, lifter folded in
    fb_sparse: tuple[np.ndarray, np.ndarray, np.ndarray] | None  # the numba kernel's sparse filterbank


@functools.lru_cache(maxsize=32)
def _tables(config: MfccConfig, kernel: str) -> _Tables:
    """Build a configuration's tables once (a few ms of Python loops): a live server opens a stream
    per session, and on its event loop that build would delay every other session's frames."""
    fmax = config.sample_rate_hz / 2 if config.fmax_hz is None else config.fmax_hz
    fbank = mel_filterbank(
        sample_rate_hz=int(config.sample_rate_hz),
        n_fft=config.n_fft,
        n_mels=config.n_mels,
        fmin_hz=config.fmin_hz,
        fmax_hz=fmax,
    )
    if config.warp != 1.0:
        fbank = warp_filterbank(fbank, sample_rate_hz=int(config.sample_rate_hz), n_fft=config.n_fft, warp=config.warp)
    window = np.hamming(config.window_len)
    first = 0 if config.include_c0 else 1
    n = np.arange(first, config.n_ceps + 1)
    # Orthonormal DCT-II rows c_first..c_n as one matrix, with the lifter folded in:
    # one small matmul per frame instead of a DCT call and a multiply.
    dct = scipy.fft.dct(np.eye(config.n_mels), type=2, axis=0, norm="ortho")[n].T  # (n_mels, n_out)
    if config.lifter > 0:
        dct = dct * (1.0 + (config.lifter / 2.0) * np.sin(np.pi * n / config.lifter))
    dct = np.ascontiguousarray(dct)
    fb_sparse = None
    if kernel == "numba":
        from realtime_core.features.compiled import sparse_filterbank

        fb_sparse = sparse_filterbank(fbank)
    arrays = [fbank, window, dct, *(fb_sparse or ())]
    for a in arrays:
        a.flags.writeable = False  # shared between streams: nobody may change them
    return _Tables(fbank, window, dct, fb_sparse)


class MfccStream:
    """Streaming MFCC extractor with the push/flush contract.

    ``push(samples)`` takes any number of samples (``(n,)`` float32/float64 in [-1, 1] or
    int16) and returns the rows now complete: ``(k, n_outputs) float64``; ``flush()`` ends
    the utterance and returns the rest (zero-padded). The same rows come out however the
    input is chunked, to rounding (module docstring). After ``flush()`` the stream is finished; make a
    new one (cheap) or call :meth:`reset`.
    """

    def __init__(self, config: MfccConfig, *, kernel: str = "numba") -> None:
        """kernel: "numba" (the spectrum-to-cepstra step compiled, :mod:`realtime_core.features.compiled`)
        or "numpy" (the reference; the two agree to rounding)."""
        if kernel not in ("numba", "numpy"):
            raise ConfigError(f"kernel must be 'numba' or 'numpy', got {kernel!r}")
        self.config = config
        self.kernel = kernel
        if kernel == "numba":
            # Imported here: numba's import costs ~0.5 s, paid only by streams that use it.
            from realtime_core.features.compiled import frames_push, spectrum_to_ceps

            self._spectrum_to_ceps = spectrum_to_ceps
            self._frames_push = frames_push
        tables = _tables(config, kernel)
        self._fbank = tables.fbank
        self._window = tables.window
        self._dct = tables.dct
        if kernel == "numba":
            assert tables.fb_sparse is not None  # built for the numba kernel
            self._fb_sparse = tables.fb_sparse
        self.reset()

    def reset(self) -> None:
        """Start a new utterance."""
        if self.kernel == "numba":
            # The compiled framing's state (:func:`realtime_core.features.compiled.frames_push`), kept in
            # place: a preallocated buffer and [n_buf, buf_start, n_received, next_frame], [last sample].
            self._cbuf = np.zeros(4 * self.config.window_len)
            self._ist = np.zeros(4, dtype=np.int64)
            self._last = np.zeros(1)
        self._buf = np.zeros(0)  # pre-emphasised samples from absolute index self._buf_start
        self._buf_start = 0
        self._n_received = 0
        self._next_frame = 0
        self._last_sample = 0.0
        self._finished = False

    @property
    def frames_emitted(self) -> int:
        """Rows returned so far in this utterance."""
        return int(self._ist[3]) if self.kernel == "numba" else self._next_frame

    @property
    def samples_received(self) -> int:
        """Samples pushed so far in this utterance."""
        return int(self._ist[2]) if self.kernel == "numba" else self._n_received

    def push(self, samples: np.ndarray) -> np.ndarray:
        """Add samples; return the newly complete rows, ``(k, n_outputs) float64``."""
        if self._finished:
            raise StreamStateError("MfccStream.push() after flush(); call reset() first")
        x = as_float_samples(samples)
        if self.kernel == "numba":
            return self._compiled_emit(x, final=False)
        if x.size:
            pre = np.empty_like(x)
            pre[0] = x[0] - self.config.preemphasis * self._last_sample
            pre[1:] = x[1:] - self.config.preemphasis * x[:-1]
            self._last_sample = float(x[-1])
            self._buf = np.concatenate([self._buf, pre])
            self._n_received += x.size
        return self._emit(final=False)

    def flush(self) -> np.ndarray:
        """End the utterance; return the remaining rows (zero-padded past the end)."""
        if self._finished:
            raise StreamStateError("MfccStream.flush() called twice; call reset() first")
        out = self._compiled_emit(np.zeros(0), final=True) if self.kernel == "numba" else self._emit(final=True)
        self._finished = True
        return out

    def _compiled_emit(self, x: np.ndarray, *, final: bool) -> np.ndarray:
        """:meth:`push` / :meth:`flush` with the framing compiled (pre-emphasis, buffer, frames, window
        in one call on preallocated state; :meth:`_emit` is the reference), then the FFT and the
        compiled spectrum-to-cepstra step."""
        cfg = self.config
        frames, self._cbuf = self._frames_push(
            x,
            self._cbuf,
            self._ist,
            self._last,
            cfg.preemphasis,
            int(cfg.sample_rate_hz),
            int(cfg.frame_rate_hz),
            self._window,
            final,
        )
        if not len(frames):
            return np.zeros((0, cfg.n_outputs))
        spec = np.fft.rfft(frames, n=cfg.n_fft, axis=1)
        return self._spectrum_to_ceps(spec, 1.0 / cfg.n_fft, *self._fb_sparse, cfg.energy_floor, self._dct)

    def _emit(self, *, final: bool) -> np.ndarray:
        cfg = self.config
        win = cfg.window_len
        ks = []
        k = self._next_frame
        while True:
            start = cfg.frame_start(k)
            if final:
                if start >= self._n_received:
                    break
            elif start + win > self._n_received:
                break
            ks.append(start)
            k += 1
        if not ks:
            return np.zeros((0, cfg.n_outputs))
        need = ks[-1] - self._buf_start + win
        if need > self._buf.size:  # only on flush: zero-pad past the end of the audio
            self._buf = np.concatenate([self._buf, np.zeros(need - self._buf.size)])
        if len(ks) == 1:  # the live case (one frame per push): a slice, not a gather
            s0 = ks[0] - self._buf_start
            frames = self._buf[None, s0 : s0 + win]
        else:
            starts = np.asarray(ks) - self._buf_start
            frames = self._buf[starts[:, None] + np.arange(win)[None, :]]
        self._next_frame = k
        drop = cfg.frame_start(k) - self._buf_start
        drop = min(drop, self._buf.size)
        self._buf = self._buf[drop:]
        self._buf_start += drop
        return self._frames_to_ceps(frames)

    def _frames_to_ceps(self, frames: np.ndarray) -> np.ndarray:
        """``(k, window_len)`` pre-emphasised samples -> ``(k, n_outputs)`` cepstra."""
        # numpy's pocketfft: measured ~10% faster than scipy.fft on this one-frame-per-call path.
        spec = np.fft.rfft(frames * self._window, n=self.config.n_fft, axis=1)
        if self.kernel == "numba":
            cfg = self.config
            return self._spectrum_to_ceps(spec, 1.0 / cfg.n_fft, *self._fb_sparse, cfg.energy_floor, self._dct)
        power = (spec.real**2 + spec.imag**2) * (1.0 / self.config.n_fft)
        energies = np.maximum(power @ self._fbank, self.config.energy_floor)
        return np.log(energies) @ self._dct


def frame_log_energy_db(samples: np.ndarray, config: MfccConfig) -> np.ndarray:
    """Per-frame RMS level in dBFS on the same frame grid as :class:`MfccStream`.

    ``samples``: ``(n,)`` mono (float in [-1, 1] or int16). Returns ``(n_frames,) float64``
    with ``n_frames = config.n_frames_for(n)``; frames past the end are zero-padded.
    Used for the loudness baseline and for speech gating.
    """
    x = as_float_samples(samples)
    n_frames = config.n_frames_for(x.size)
    win = config.window_len
    starts = np.array([config.frame_start(k) for k in range(n_frames)], dtype=np.int64)
    padded = np.concatenate([x, np.zeros(win)])
    frames = padded[starts[:, None] + np.arange(win)[None, :]]
    rms2 = np.mean(frames**2, axis=1)
    return 10.0 * np.log10(np.maximum(rms2, 1e-12))


def loudness_db(samples: np.ndarray, rate_hz: int, n_frames: int) -> np.ndarray:
    """The one per-frame level of facecast: ``(n_frames,) float64`` RMS level in dBFS on the 30 fps
    analysis grid of :class:`MfccStream` at ``rate_hz`` (:func:`frame_log_energy_db`), truncated or
    padded with the quietest frame's level to exactly ``n_frames`` (a track's length). The loudness
    baseline of ``facecast eval``, the speech-energy check of ``facecast extract`` and its plots."""
    lv = frame_log_energy_db(samples, MfccConfig(sample_rate_hz=int(rate_hz)))
    out = np.full(n_frames, lv.min() if len(lv) else -120.0)
    out[: min(n_frames, len(lv))] = lv[:n_frames]
    return out


def mfcc(samples: np.ndarray, config: MfccConfig) -> np.ndarray:
    """Whole-utterance MFCCs: ``(n,)`` samples -> ``(ceil(n * fps / rate), n_outputs) float64``.

    What :class:`MfccStream` gives for the same samples pushed whole and flushed (exactly), or in any
    chunks (to rounding). Raises :class:`InvalidAudioError` for audio shorter than one window.
    """
    x = as_float_samples(samples)
    if x.size < config.window_len:
        raise InvalidAudioError(
            f"audio too short: {x.size} samples, need at least one analysis window of "
            f"{config.window_len} samples ({1000.0 * config.window_len / config.sample_rate_hz:.1f} ms)"
        )
    stream = MfccStream(config)
    head = stream.push(x)
    return np.concatenate([head, stream.flush()])
