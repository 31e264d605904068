"""Test inputs made here: speech-like audio and small random models (no shared data needed).

The shipped default model may not exist on a fresh checkout, so tests build their own small model
(a random well-posed AV-HMM with the default front end's shape but fewer cepstra) and pass it
explicitly.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from realtime_core.avmodel import AvModel
from realtime_core.features import FrontEndConfig, MfccConfig
from realtime_core.hmm.sampling import random_av_hmm


def small_model(seed: int = 0, *, n_ceps: int = 5, tc: int = 3) -> AvModel:
    """A small model at 16 kHz: n_ceps cepstra, tc frames of context, 4 states x 2 mixtures."""
    fe = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000, n_ceps=n_ceps), tc=tc)
    hmm = random_av_hmm(np.random.default_rng(seed), n_states=4, n_mix=2, n_audio=(2 * tc + 1) * n_ceps, n_visual=4)
    return AvModel(
        hmm=hmm, frontend=fe, cmvn_mean=np.zeros(n_ceps), cmvn_var=np.ones(n_ceps), metadata={"recipe": "test"}
    )


def speechlike(seconds: float, rate_hz: int, seed: int = 0) -> np.ndarray:
    """(n,) float32 in [-1, 1]: voiced harmonics and noise bursts with a syllable-rate envelope."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate_hz)
    t = np.arange(n) / rate_hz
    f0 = 120 + 30 * np.sin(2 * np.pi * 0.7 * t)
    phase = 2 * np.pi * np.cumsum(f0) / rate_hz
    voiced = sum(np.sin(h * phase) / h for h in range(1, 12))
    env = np.clip(np.sin(2 * np.pi * 3.1 * t), 0, None) ** 1.5
    noise = rng.standard_normal(n) * (np.sin(2 * np.pi * 1.3 * t) > 0.6)
    x = 0.25 * env * voiced + 0.05 * noise
    return (x / np.abs(x).max() * 0.8).astype(np.float32)


def plausible_model(seed: int = 0) -> AvModel:
    """The server tests' random model with its visual space mapped affinely (o_v' = s o_v + c) into
    the mouth parameters' typical ranges (a few hundredths of an IOD, the mouth opening 0 .. 0.3 IOD):
    the inversion is affine-equivariant in o_v, so outputs move like speech would move a mouth
    instead of by several IOD (a random model's raw outputs tear the face apart)."""
    m = small_model(seed)
    hmm = m.hmm
    na = hmm.n_audio
    s = np.array([0.012, 0.025, 0.022, 0.005])
    c = np.array([0.0, 0.0, 0.22, 0.0])
    means = hmm.means.copy()
    means[..., na:] = means[..., na:] * s + c
    cov = hmm.covars.copy()
    cov[..., na:, :] *= s[:, None]
    cov[..., :, na:] *= s[None, :]
    return replace(m, hmm=replace(hmm, means=means, covars=cov))


def cut_mid_word(seconds: float, seed: int) -> np.ndarray:
    """``seconds`` of speech-like 16 kHz audio cut short at the loudest 20 ms block of its last 2 s: the
    session ends mid-word, its last frames with the mouth open."""
    x = speechlike(seconds, 16000, seed=seed)
    blocks = x[: len(x) // 320 * 320].reshape(-1, 320)
    tail = len(blocks) - 100  # the last 2 s
    loudest = tail + int(np.argmax((blocks[tail:] ** 2).mean(axis=1)))
    return x[: (loudest + 1) * 320]
