"""What a real microphone does to speech: reverberation, noise, level, sample rate.

The chain (in this order, each step seeded from one ``numpy.random.Generator``):

1. reverberation (probability ``reverb_prob``): convolution with a synthetic room impulse
   response: a direct path plus exponentially decaying Gaussian noise whose energy falls by
   60 dB in ``rt60_s`` (drawn from ``rt60_range_s``), mixed at a direct-to-reverberant ratio
   from ``drr_range_db``. The output keeps the input's length (the tail is cut) and RMS.
2. additive noise at an SNR drawn from ``snr_range_db`` (10-30 dB), white or pink (1/f, made
   by shaping white noise's spectrum), relative to the speech's RMS over the utterance.
3. level change by a gain drawn from ``gain_range_db``; if a peak would exceed 0.99 full
   scale the whole utterance is scaled down (a careful recordist's limiter, not clipping).
4. resampling to a rate drawn from ``sample_rates_hz`` with ``scipy.signal.resample_poly``
   (polyphase, anti-aliased). Duration is preserved, so the 30 fps labels stay valid.

Timing never changes (no time stretch or delay beyond the IR's direct path at lag 0), so
the mouth-parameter track of the clean utterance labels the augmented one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import fftconvolve

from realtime_core.features.resample import resample_audio
from training.errors import ConfigError

NOISE_KINDS = ("white", "pink")


@dataclass(frozen=True)
class AugmentConfig:
    """Ranges of the augmentation draws (uniform within each range)."""

    reverb_prob: float = 0.5
    rt60_range_s: tuple[float, float] = (0.15, 0.5)
    drr_range_db: tuple[float, float] = (3.0, 12.0)
    noise_prob: float = 0.8
    snr_range_db: tuple[float, float] = (10.0, 30.0)
    noise_kinds: tuple[str, ...] = NOISE_KINDS
    gain_range_db: tuple[float, float] = (-18.0, 3.0)
    sample_rates_hz: tuple[int, ...] = (8000, 16000, 22050, 44100)

    def __post_init__(self) -> None:
        for name in ("reverb_prob", "noise_prob"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"{name} must be in [0, 1], got {getattr(self, name)}")
        for name in ("rt60_range_s", "drr_range_db", "snr_range_db", "gain_range_db"):
            lo, hi = getattr(self, name)
            if lo > hi:
                raise ConfigError(f"{name} must be (low, high), got {(lo, hi)}")
        if self.rt60_range_s[0] <= 0:
            raise ConfigError("rt60 must be > 0 s")
        if not self.sample_rates_hz or min(self.sample_rates_hz) < 4000:
            raise ConfigError(f"sample_rates_hz must be rates >= 4000 Hz, got {self.sample_rates_hz}")
        unknown = set(self.noise_kinds) - set(NOISE_KINDS)
        if not self.noise_kinds or unknown:
            raise ConfigError(f"noise_kinds must be among {NOISE_KINDS}, got {self.noise_kinds}")


@dataclass(frozen=True)
class Augmented:
    """Result of :func:`augment`: samples (n',) float32 in [-1, 1] at ``sample_rate_hz``, and
    ``info``, the drawn settings (JSON-ready, kept in the manifest for auditing)."""

    samples: np.ndarray
    sample_rate_hz: int
    info: dict = field(default_factory=dict)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x, dtype=np.float64)))) if len(x) else 0.0


def room_impulse_response(rate_hz: int, rt60_s: float, drr_db: float, rng: np.random.Generator) -> np.ndarray:
    """Synthetic IR, shape (round(rt60_s * rate_hz),) float64: 1 at lag 0 then a noise tail
    decaying by 60 dB over ``rt60_s`` whose energy is ``drr_db`` below the direct path's."""
    n = max(int(round(rt60_s * rate_hz)), 2)
    t = np.arange(n) / rate_hz
    tail = rng.standard_normal(n) * np.exp(-3.0 * np.log(10.0) * t / rt60_s)  # -60 dB at rt60
    tail[0] = 0.0
    tail *= np.sqrt(10.0 ** (-drr_db / 10.0) / max(np.sum(tail**2), 1e-12))
    tail[0] = 1.0
    return tail


def coloured_noise(n: int, kind: str, rng: np.random.Generator) -> np.ndarray:
    """(n,) float64 unit-RMS noise; "pink" has a 1/f power spectrum (-3 dB/octave)."""
    white = rng.standard_normal(n)
    if kind == "pink" and n > 1:
        spec = np.fft.rfft(white)
        f = np.arange(len(spec), dtype=np.float64)
        f[0] = 1.0
        white = np.fft.irfft(spec / np.sqrt(f), n)
    return white / max(_rms(white), 1e-12)


def augment(
    samples: np.ndarray, rate_hz: int, rng: np.random.Generator, config: AugmentConfig = AugmentConfig()
) -> Augmented:
    """Degrade one utterance like a real microphone would (see the module doc).

    samples: (n,) float in [-1, 1] at ``rate_hz``. Returns float32 samples in [-1, 1].
    """
    x = np.asarray(samples, dtype=np.float64)
    if x.ndim != 1 or len(x) == 0:
        raise ConfigError(f"augment needs a non-empty 1-D signal, got shape {x.shape}")
    info: dict = {}
    speech_rms = _rms(x)
    if rng.random() < config.reverb_prob:
        rt60 = float(rng.uniform(*config.rt60_range_s))
        drr = float(rng.uniform(*config.drr_range_db))
        ir = room_impulse_response(rate_hz, rt60, drr, rng)
        x = fftconvolve(x, ir)[: len(x)]
        x *= speech_rms / max(_rms(x), 1e-12)
        info["reverb"] = {"rt60_s": round(rt60, 4), "drr_db": round(drr, 2)}
    if rng.random() < config.noise_prob:
        snr = float(rng.uniform(*config.snr_range_db))
        kind = config.noise_kinds[int(rng.integers(len(config.noise_kinds)))]
        x = x + coloured_noise(len(x), kind, rng) * speech_rms * 10.0 ** (-snr / 20.0)
        info["noise"] = {"kind": kind, "snr_db": round(snr, 2)}
    gain_db = float(rng.uniform(*config.gain_range_db))
    x *= 10.0 ** (gain_db / 20.0)
    peak = float(np.max(np.abs(x)))
    if peak > 0.99:
        x *= 0.99 / peak
        gain_db += 20.0 * np.log10(0.99 / peak)
    info["gain_db"] = round(gain_db, 2)
    to_hz = int(config.sample_rates_hz[int(rng.integers(len(config.sample_rates_hz)))])
    x = resample_audio(x, rate_hz, to_hz)
    info["sample_rate_hz"] = to_hz
    return Augmented(np.clip(x, -1.0, 1.0).astype(np.float32), to_hz, info)
