"""The joint audio-visual HMM (paper Sec. 4) and its Gaussian-mixture emissions.

An ergodic N-state HMM whose state j emits ``b_j(o) = sum_k c_jk N(o; mu_jk, Sigma_jk)``
over the joint vector ``o = [o_a; o_v]`` (eq. 1). Covariances are full (the paper's
proposal) or diagonal (for the paper's Table 1 comparison).

All Gaussian work goes through Cholesky factors: ``Sigma = L L^T`` with L lower
triangular, so ``log N(x) = -0.5 |L^-1 (x - mu)|^2 - sum(log diag L) - D/2 log(2 pi)``
with a triangular solve; no covariance matrix is ever inverted.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg

from realtime_core.errors import ConfigError, ModelFormatError

LOG_2PI = float(np.log(2.0 * np.pi))
COVARIANCE_TYPES = ("full", "diag")


@dataclass(frozen=True, kw_only=True, eq=False)
class AvHmm:
    """Parameters of the audio-visual HMM. Validated at construction.

    startprob: ``(N,)``; transmat: ``(N, N)`` rows sum to 1; weights: ``(N, M)`` rows sum to 1;
    means: ``(N, M, D)``; covars: ``(N, M, D, D)`` (full) or ``(N, M, D)`` (diag variances);
    n_audio: the first ``n_audio`` of the D dimensions are o_a, the rest o_v.
    """

    startprob: np.ndarray
    transmat: np.ndarray
    weights: np.ndarray
    means: np.ndarray
    covars: np.ndarray
    covariance_type: str = "full"
    n_audio: int

    def __post_init__(self) -> None:
        if self.covariance_type not in COVARIANCE_TYPES:
            raise ConfigError(f"covariance_type must be one of {COVARIANCE_TYPES}, got {self.covariance_type!r}")
        for name in ("startprob", "transmat", "weights", "means", "covars"):
            arr = np.asarray(getattr(self, name), dtype=np.float64)
            if not np.all(np.isfinite(arr)):
                raise ModelFormatError(f"{name} contains NaN or inf")
            object.__setattr__(self, name, arr)
        if self.means.ndim != 3:
            raise ModelFormatError(f"means must be (N, M, D), got shape {self.means.shape}")
        n, m, d = self.means.shape
        expect = {
            "startprob": (n,),
            "transmat": (n, n),
            "weights": (n, m),
            "covars": (n, m, d, d) if self.covariance_type == "full" else (n, m, d),
        }
        for name, shape in expect.items():
            if getattr(self, name).shape != shape:
                raise ModelFormatError(f"{name} must have shape {shape}, got {getattr(self, name).shape}")
        if not 1 <= self.n_audio < d:
            raise ModelFormatError(f"n_audio must be in 1..D-1 = {d - 1}, got {self.n_audio}")
        for name, axis in (("startprob", 0), ("transmat", 1), ("weights", 1)):
            arr = getattr(self, name)
            if np.any(arr < 0) or not np.allclose(arr.sum(axis=axis), 1.0, atol=1e-6):
                raise ModelFormatError(f"{name} must be non-negative and sum to 1 along axis {axis}")
        if self.covariance_type == "full":
            if not np.allclose(self.covars, np.swapaxes(self.covars, -1, -2), rtol=1e-8, atol=1e-10):
                raise ModelFormatError("covars must be symmetric")
            _ = self.chol  # raises ModelFormatError naming the component if not PD
        elif np.any(self.covars <= 0):
            j, k, _i = np.argwhere(self.covars <= 0)[0]
            raise ModelFormatError(f"diagonal covariance of state {j}, mixture {k} is not positive")

    @property
    def n_states(self) -> int:
        return self.means.shape[0]

    @property
    def n_mix(self) -> int:
        return self.means.shape[1]

    @property
    def n_dim(self) -> int:
        return self.means.shape[2]

    @property
    def n_visual(self) -> int:
        return self.n_dim - self.n_audio

    @cached_property
    def chol(self) -> np.ndarray:
        """Lower Cholesky factors ``(N, M, D, D)``; for diag, ``diag(sqrt(var))``."""
        if self.covariance_type == "diag":
            out = np.zeros((*self.means.shape, self.n_dim))
            idx = np.arange(self.n_dim)
            out[..., idx, idx] = np.sqrt(self.covars)
            return out
        try:
            return np.linalg.cholesky(self.covars)
        except np.linalg.LinAlgError:
            for j in range(self.n_states):
                for k in range(self.n_mix):
                    try:
                        np.linalg.cholesky(self.covars[j, k])
                    except np.linalg.LinAlgError:
                        raise ModelFormatError(
                            f"covariance of state {j}, mixture {k} is not positive definite"
                        ) from None
            raise

    @property
    def log_startprob(self) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.log(self.startprob)

    @property
    def log_transmat(self) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.log(self.transmat)

    @property
    def log_weights(self) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return np.log(self.weights)


def quadratic_features(x: np.ndarray) -> np.ndarray:
    """``(T, D) -> (T, D (D + 1) / 2 + D)``: the products ``x_i x_j`` (i <= j), then ``x``.

    Against these, a Gaussian's quadratic form is one dot product (see
    :func:`quadratic_coefficients`), so all components share one GEMM over the frames.
    """
    return quadratic_features_t(np.ascontiguousarray(x.T)).T


def quadratic_features_t(xt: np.ndarray) -> np.ndarray:
    """The same, transposed: ``(D, T) -> (K, T)``. Gathering whole rows (contiguous frames)
    is several times faster than gathering columns, so the training E-step uses this layout."""
    i0, i1 = np.triu_indices(xt.shape[0])
    return np.concatenate([xt[i0] * xt[i1], xt], axis=0)


def quadratic_coefficients(means: np.ndarray, chol: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of ``(x - mu_c)^T Sigma_c^-1 (x - mu_c) + log|Sigma_c| + D log 2 pi``.

    ``means``: ``(C, D)``; ``chol``: ``(C, D, D)`` lower Cholesky factors. Returns
    ``(Q (C, K), q0 (C,))`` with ``-0.5 (quadratic_features(x) @ Q.T + q0)`` the log densities.
    ``Sigma^-1 = W^T W`` with ``W = L^-1`` from triangular solves (no covariance is inverted).
    """
    c, d = means.shape
    i0, i1 = np.triu_indices(d)
    weight = np.where(i0 == i1, 1.0, 2.0)
    eye = np.eye(d)
    Q = np.empty((c, i0.size + d))
    q0 = np.empty(c)
    for k in range(c):
        W = scipy.linalg.solve_triangular(chol[k], eye, lower=True, check_finite=False)
        P = W.T @ W
        Pm = P @ means[k]
        Q[k, : i0.size] = P[i0, i1] * weight
        Q[k, i0.size :] = -2.0 * Pm
        q0[k] = means[k] @ Pm + 2.0 * np.log(np.diagonal(chol[k])).sum() + d * LOG_2PI
    return Q, q0


def gaussian_loglik(x: np.ndarray, means: np.ndarray, chol: np.ndarray, *, chunk: int = 1024) -> np.ndarray:
    """Log densities of every frame under every Gaussian.

    ``x``: ``(T, D)``; ``means``: ``(C, D)``; ``chol``: ``(C, D, D)`` lower Cholesky factors.
    Returns ``(T, C)``. The quadratic forms are expanded (:func:`quadratic_coefficients`)
    around the frames' mean, so a chunk of frames costs one ``(t, K) x (K, C)`` GEMM: about
    a quarter of the flops of whitening the frames for every component.
    """
    origin = x.mean(axis=0)
    Q, q0 = quadratic_coefficients(means - origin, chol)
    out = np.empty((x.shape[0], means.shape[0]))
    for s in range(0, x.shape[0], chunk):
        u = quadratic_features_t(np.ascontiguousarray((x[s : s + chunk] - origin).T))  # (K, t)
        out[s : s + chunk] = -0.5 * (Q @ u + q0[:, None]).T
    return out


def diag_gaussian_loglik(x: np.ndarray, means: np.ndarray, var: np.ndarray) -> np.ndarray:
    """``(T, D), (C, D), (C, D) variances -> (T, C)`` log densities, vectorised."""
    prec = 1.0 / var
    quad = (x**2) @ prec.T - 2.0 * x @ (means * prec).T + np.sum(means**2 * prec, axis=1)
    return -0.5 * (quad + np.sum(np.log(var), axis=1) + x.shape[1] * LOG_2PI)


def component_loglik(model: AvHmm, x: np.ndarray) -> np.ndarray:
    """``log c_jk + log N(x_t; mu_jk, Sigma_jk)`` for the joint model: ``(T, D) -> (T, N, M)``."""
    if x.ndim != 2 or x.shape[1] != model.n_dim:
        raise ModelFormatError(f"observations must be (T, {model.n_dim}), got {x.shape}")
    n, m, d = model.means.shape
    mu = model.means.reshape(n * m, d)
    if model.covariance_type == "diag":
        ll = diag_gaussian_loglik(x, mu, model.covars.reshape(n * m, d))
    else:
        ll = gaussian_loglik(x, mu, model.chol.reshape(n * m, d, d))
    return ll.reshape(-1, n, m) + model.log_weights[None]
