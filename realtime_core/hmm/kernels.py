"""Forward-backward and Viterbi kernels, independent of the emission model.

Theory of operation
-------------------
Every kernel takes per-frame log emission likelihoods ``log_b`` of shape ``(T, N)`` and the
log start/transition probabilities; the emission model (Gaussian mixtures, audio-only
marginals, ...) is computed elsewhere, as in hmmlearn's split.

The recursions are kept in log space, but each step is evaluated as
``log(exp(alpha - max) @ A) + max``: one small matrix-vector product per frame instead
of an ``(N, N)`` logsumexp, with the same numerical range (the shift keeps the largest
term at exp(0) = 1). Zero transition probabilities stay exact zeros.
"""

from __future__ import annotations

import numpy as np

from realtime_core.errors import InvalidFeaturesError


def _check(log_startprob: np.ndarray, log_transmat: np.ndarray, log_b: np.ndarray) -> int:
    n = log_startprob.shape[0]
    if log_transmat.shape != (n, n) or log_b.ndim != 2 or log_b.shape[1] != n:
        raise InvalidFeaturesError(
            f"shape mismatch: startprob {log_startprob.shape}, transmat {log_transmat.shape}, log_b {log_b.shape}"
        )
    if log_b.shape[0] == 0:
        raise InvalidFeaturesError("empty sequence (0 frames)")
    return n


def log_forward(log_startprob: np.ndarray, log_transmat: np.ndarray, log_b: np.ndarray) -> tuple[np.ndarray, float]:
    """Forward pass. ``(N,), (N, N), (T, N) -> (log_alpha (T, N), log P(O))``.

    ``log_alpha[t, j] = log P(o_1..o_t, q_t = j)``.
    """
    _check(log_startprob, log_transmat, log_b)
    T, n = log_b.shape
    A = np.exp(log_transmat)
    la = np.empty((T, n))
    la[0] = log_startprob + log_b[0]
    with np.errstate(divide="ignore"):
        for t in range(1, T):
            prev = la[t - 1]
            m = prev.max()
            la[t] = np.log(np.exp(prev - m) @ A) + m + log_b[t]
    m = la[-1].max()
    return la, float(m + np.log(np.exp(la[-1] - m).sum()))


def log_backward(log_transmat: np.ndarray, log_b: np.ndarray) -> np.ndarray:
    """Backward pass. ``(N, N), (T, N) -> log_beta (T, N)``.

    ``log_beta[t, i] = log P(o_{t+1}..o_T | q_t = i)``.
    """
    T, n = log_b.shape
    A = np.exp(log_transmat)
    lb = np.empty((T, n))
    lb[-1] = 0.0
    with np.errstate(divide="ignore"):
        for t in range(T - 2, -1, -1):
            nxt = lb[t + 1] + log_b[t + 1]
            m = nxt.max()
            lb[t] = np.log(A @ np.exp(nxt - m)) + m
    return lb


def forward_backward(
    log_startprob: np.ndarray, log_transmat: np.ndarray, log_b: np.ndarray
) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """State posteriors. Returns ``(gamma (T, N), log P(O), log_alpha, log_beta)``.

    ``gamma[t, j] = P(q_t = j | O)``; rows sum to 1.
    """
    la, loglik = log_forward(log_startprob, log_transmat, log_b)
    lb = log_backward(log_transmat, log_b)
    lg = la + lb
    lg -= lg.max(axis=1, keepdims=True)
    gamma = np.exp(lg)
    gamma /= gamma.sum(axis=1, keepdims=True)
    return gamma, loglik, la, lb


def expected_transitions(
    log_alpha: np.ndarray, log_beta: np.ndarray, log_transmat: np.ndarray, log_b: np.ndarray, loglik: float
) -> np.ndarray:
    """Expected transition counts ``sum_t xi_t(i, j)``, ``(N, N)``.

    ``xi_t(i, j) = P(q_t = i, q_{t+1} = j | O)`` for t = 1..T-1.
    """
    if log_b.shape[0] < 2:
        return np.zeros_like(log_transmat)
    a = log_alpha[:-1]
    bb = log_b[1:] + log_beta[1:]
    ma = a.max(axis=1, keepdims=True)
    mb = bb.max(axis=1, keepdims=True)
    ea = np.exp(a - ma)  # (T-1, N)
    eb = np.exp(bb - mb)  # (T-1, N)
    scale = np.exp(ma[:, 0] + mb[:, 0] - loglik)  # (T-1,)
    # sum_t scale_t * ea_t[i] * A[i, j] * eb_t[j]
    return np.exp(log_transmat) * ((ea * scale[:, None]).T @ eb)


def viterbi(log_startprob: np.ndarray, log_transmat: np.ndarray, log_b: np.ndarray) -> tuple[np.ndarray, float]:
    """Most likely state path. ``-> (path (T,) int64, log P(O, path))``."""
    _check(log_startprob, log_transmat, log_b)
    T, n = log_b.shape
    delta = log_startprob + log_b[0]
    back = np.empty((T, n), dtype=np.int64)
    back[0] = 0
    for t in range(1, T):
        scores = delta[:, None] + log_transmat  # (from, to)
        back[t] = np.argmax(scores, axis=0)
        delta = scores[back[t], np.arange(n)] + log_b[t]
    path = np.empty(T, dtype=np.int64)
    path[-1] = int(np.argmax(delta))
    for t in range(T - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path, float(delta[path[-1]])
