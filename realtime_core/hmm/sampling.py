"""Sampling from an audio-visual HMM, and random well-posed models (tests, benchmarks)."""

from __future__ import annotations

import numpy as np

from realtime_core.hmm import AvHmm


def random_av_hmm(
    rng: np.random.Generator,
    *,
    n_states: int,
    n_mix: int,
    n_audio: int,
    n_visual: int,
    coupling: float = 0.8,
    self_loop: float = 0.8,
) -> AvHmm:
    """A well-separated AV-HMM whose visual part depends on the audio part within each
    component (cross-covariance), so inversion has something to recover."""
    d = n_audio + n_visual
    means = np.empty((n_states, n_mix, d))
    covars = np.empty((n_states, n_mix, d, d))
    for j in range(n_states):
        centre = rng.standard_normal(d) * 2.5
        for k in range(n_mix):
            means[j, k] = centre + rng.standard_normal(d) * 0.8
            # o_v = G o_a + noise within the component: a PD joint covariance by construction.
            a = rng.standard_normal((n_audio, n_audio)) * 0.25
            caa = a @ a.T + np.eye(n_audio) * 0.3
            g = rng.standard_normal((n_visual, n_audio)) * coupling / np.sqrt(n_audio)
            b = rng.standard_normal((n_visual, n_visual)) * 0.1
            cov = np.empty((d, d))
            cov[:n_audio, :n_audio] = caa
            cov[n_audio:, :n_audio] = g @ caa
            cov[:n_audio, n_audio:] = (g @ caa).T
            cov[n_audio:, n_audio:] = g @ caa @ g.T + b @ b.T + np.eye(n_visual) * 0.05
            covars[j, k] = 0.5 * (cov + cov.T)
    trans = rng.dirichlet(np.ones(n_states), size=n_states) * (1 - self_loop) + np.eye(n_states) * self_loop
    return AvHmm(
        startprob=np.full(n_states, 1.0 / n_states),
        transmat=trans,
        weights=rng.dirichlet(np.ones(n_mix) * 5, size=n_states),
        means=means,
        covars=covars,
        n_audio=n_audio,
    )


def sample(model: AvHmm, rng: np.random.Generator, length: int) -> tuple[np.ndarray, np.ndarray]:
    """``(length, D)`` observations and ``(length,)`` state path drawn from ``model``."""
    states = np.empty(length, dtype=int)
    q = rng.choice(model.n_states, p=model.startprob)
    for t in range(length):
        states[t] = q
        q = rng.choice(model.n_states, p=model.transmat[q])
    comps = np.array([rng.choice(model.n_mix, p=model.weights[s]) for s in states])
    chol = np.linalg.cholesky(model.covars)
    z = rng.standard_normal((length, model.n_dim))
    x = model.means[states, comps] + np.einsum("tij,tj->ti", chol[states, comps], z)
    return x, states
