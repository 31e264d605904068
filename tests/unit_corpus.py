"""Test inputs of the unit-selection tests: synthetic face tracks (lower face moving with 3 latent
gestures) and one ARPAbet phone per viseme class (fixtures ``corpus_rows``, ``stored_corpus``,
``corpus_file`` in tests/conftest.py build a small corpus from them with the real builder)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from realtime_core.synthesis.visemes import PHONE_TO_VISEME, VISEMES

ARPABET_BY_VISEME = {v: next(p for p, c in PHONE_TO_VISEME["arpabet"].items() if c == v) for v in VISEMES}


def synthetic_track(rng: np.random.Generator, n_frames: int):
    """A FaceTrack whose lower face moves smoothly (3 latent gestures) and whose params follow them."""
    from training.facetrack import LOWER_FACE, N_LANDMARKS, FaceTrack

    t = np.arange(n_frames) / 30.0
    gestures = np.stack([np.sin(rng.uniform(3, 9) * t + rng.uniform(0, 6)) for _ in range(3)], axis=1)
    neutral = rng.normal(size=(N_LANDMARKS, 3)).astype(np.float32)
    basis = np.random.default_rng(99).normal(scale=0.02, size=(3, len(LOWER_FACE), 3))
    lm = np.repeat(neutral[None], n_frames, axis=0).astype(np.float64)
    lm[:, list(LOWER_FACE)] += np.einsum("tg,gpc->tpc", gestures, basis)
    params = np.stack(
        [0.02 * gestures[:, 0], 0.05 * gestures[:, 1], 0.1 + 0.1 * gestures[:, 2], 0.01 * gestures[:, 0]], axis=1
    )
    return FaceTrack(
        source=Path("synthetic.mp4"),
        samples=np.zeros(n_frames * 533, np.float32),
        sample_rate_hz=16000,
        landmarks=lm.astype(np.float32),
        neutral=neutral,
        params=params,
        face_found=np.ones(n_frames, bool),
        closed_gap_iod=0.0,
    )
