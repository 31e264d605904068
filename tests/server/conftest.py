"""Fixtures of the server tests: a small random model saved to disk, test speech as WAV files.

The shipped default model may not exist yet, so every test builds its own small model (a random
well-posed AV-HMM with the default front end's shape but fewer cepstra) and passes it explicitly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from realtime_core.avmodel import AvModel
from realtime_core.features import FrontEndConfig, MfccConfig
from realtime_core.hmm.sampling import random_av_hmm


def small_model(seed: int = 0, *, n_ceps: int = 5, tc: int = 3) -> AvModel:
    """A small model at 16 kHz: n_ceps cepstra, tc frames of context, 4 states x 2 mixtures."""
    fe = FrontEndConfig(mfcc=MfccConfig(sample_rate_hz=16000, n_ceps=n_ceps), tc=tc)
    hmm = random_av_hmm(np.random.default_rng(seed), n_states=4, n_mix=2, n_audio=(2 * tc + 1) * n_ceps, n_visual=4)
    return AvModel(hmm=hmm, frontend=fe, cmvn_mean=np.zeros(n_ceps), cmvn_var=np.ones(n_ceps), metadata={"recipe": "test"})


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


@pytest.fixture(scope="session")
def model() -> AvModel:
    return small_model()


@pytest.fixture(scope="session")
def model_path(tmp_path_factory, model) -> Path:
    from assets.modelfile import save_model

    return save_model(tmp_path_factory.mktemp("model") / "small.npz", model)


@pytest.fixture(scope="session")
def wav16k(tmp_path_factory) -> Path:
    """2 s of speech-like audio at 16 kHz as a pcm_s16le WAV file."""
    from assets.audio import write_wav

    path = tmp_path_factory.mktemp("audio") / "speech16k.wav"
    write_wav(path, speechlike(2.0, 16000), 16000)
    return path


@pytest.fixture(scope="session")
def wav48k(tmp_path_factory) -> Path:
    """1.5 s of speech-like audio at 48 kHz."""
    from assets.audio import write_wav

    path = tmp_path_factory.mktemp("audio") / "speech48k.wav"
    write_wav(path, speechlike(1.5, 48000, seed=1), 48000)
    return path
