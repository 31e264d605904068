"""MAP speaker adaptation of the audio side of the audio-visual HMM (Gauvain & Lee 1994).

Theory of operation
-------------------
A new voice arrives as untranscribed speech: audio features ``o_a`` only, no lips. The
adaptation therefore works on the HMM's **audio marginal**: state ``j`` emits
``sum_k w_jk N(o_a; mu_a,jk, Sigma_aa,jk)`` (the joint Gaussian's leading block, whose
Cholesky factor is the leading block of the joint one). EM on that marginal with the
conjugate priors of Gauvain & Lee, centred on the speaker-independent model:

* mean ``mu_a,c ~ N(mu0_a,c, Sigma_aa,c / tau)`` (``tau`` = relevance factor, in frames);
* weights ``w_j ~ Dirichlet(tau_w w0_j + 1)``;

gives, from the forward-backward responsibilities ``gamma_c(t)`` (state posterior times
within-state mixture posterior) with ``n_c = sum_t gamma_c(t)``:

    mu_a,c = (tau mu0_a,c + sum_t gamma_c(t) o_a(t)) / (tau + n_c)
    w_jk   = (tau_w w0_jk + n_jk) / (tau_w + n_j)

A component the new voice never visits keeps its prior; one it visits often moves to the
voice's data. Each iteration cannot lower the MAP objective
``log p(O_a | model) + log prior(model)`` (EM on a posterior), recorded per frame in
:attr:`AdaptResult.history`. With no data, the model is returned unchanged.

The visual side
---------------
Covariances, transitions, visual means and the audio->visual regressions
``R_c = Sigma_va Sigma_aa^-1`` are kept. The conditional mean used for inversion is
``m_c(o_a) = mu_v,c + R_c (o_a - mu_a,c)``: moving ``mu_a,c`` to where the new voice produces
that sound moves the regression's anchor with it, so the new voice's typical frame for
component ``c`` is mapped to the same mouth (``mu_v,c``) the training talker made there.
(Shifting ``mu_v`` by ``R_c`` times the audio shift instead would leave ``m_c`` unchanged and
adapt only which components fire.) The joint covariance is unchanged, so the joint model stays
valid and every streaming matrix is recomputed from it by
:meth:`realtime_core.inversion.ConditionalForm.from_model`.

Everything is numpy in, numpy out; reading the speech and writing the model are the caller's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from scipy.special import logsumexp

from realtime_core.errors import ConfigError, InvalidFeaturesError
from realtime_core.hmm.kernels import forward_backward, log_forward
from realtime_core.hmm.model import LOG_2PI, AvHmm


@dataclass(frozen=True, kw_only=True)
class AdaptConfig:
    """relevance: tau, the prior's weight on each audio mean in frames (Gauvain & Lee; 8-20 is
    usual for GMM-UBM speaker adaptation; ``inf``: the means kept as they are); weight_relevance: tau_w
    for the mixture weights (``None`` or ``inf``: no weight adaptation); n_iter: EM iterations; tol: stop
    when the MAP objective gains less than this per frame."""

    relevance: float = 8.0
    weight_relevance: float | None = 8.0
    n_iter: int = 5
    tol: float = 1e-4

    def __post_init__(self) -> None:
        if not self.relevance > 0:
            raise ConfigError(f"relevance must be > 0 frames, got {self.relevance}")
        if self.weight_relevance is not None and not self.weight_relevance > 0:
            raise ConfigError(f"weight_relevance must be > 0 frames or None, got {self.weight_relevance}")
        if self.n_iter < 0 or self.tol < 0:
            raise ConfigError("n_iter and tol must be >= 0")


@dataclass(frozen=True)
class AdaptResult:
    """model: the adapted HMM; history: MAP objective per frame before each M-step and at the
    end (non-decreasing); occupancy: ``(N, M)`` expected frames per component in the last
    E-step; n_frames: frames of adaptation data."""

    model: AvHmm
    history: list[float] = field(default_factory=list)
    occupancy: np.ndarray | None = None
    n_frames: int = 0


def _audio_chol(model: AvHmm) -> np.ndarray:
    """``(N M, Da, Da)`` Cholesky factors of the audio marginals (leading block of the joint)."""
    n, m, d = model.means.shape
    da = model.n_audio
    return model.chol.reshape(n * m, d, d)[:, :da, :da]


class _AudioMarginal:
    """The audio marginals' whitening matrices ``W_c = L_aa,c^-1`` and log-determinants, computed
    once: adaptation never changes a covariance, so each E-step is one whitening GEMM per component."""

    def __init__(self, model: AvHmm) -> None:
        chol = _audio_chol(model)
        da = model.n_audio
        self.whiten = np.stack(
            [scipy.linalg.solve_triangular(c, np.eye(da), lower=True, check_finite=False) for c in chol]
        )  # (C, Da, Da)
        self.const = -np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1) - 0.5 * da * LOG_2PI  # (C,)

    def loglik(self, model: AvHmm, oa: np.ndarray) -> np.ndarray:
        """``log w_jk + log N(o_a; mu_a,jk, Sigma_aa,jk)``: ``(T, Da) -> (T, N, M)``."""
        n, m, _ = model.means.shape
        da = model.n_audio
        mu = model.means[:, :, :da].reshape(n * m, da)
        out = np.empty((len(oa), n * m))
        for c in range(n * m):
            z = (oa - mu[c]) @ self.whiten[c].T
            out[:, c] = -0.5 * np.einsum("ti,ti->t", z, z) + self.const[c]
        return out.reshape(-1, n, m) + model.log_weights[None]


def audio_component_loglik(model: AvHmm, oa: np.ndarray) -> np.ndarray:
    """``log w_jk + log N(o_a; mu_a,jk, Sigma_aa,jk)``: ``(T, Da) -> (T, N, M)``."""
    da = model.n_audio
    if oa.ndim != 2 or oa.shape[1] != da:
        raise InvalidFeaturesError(f"audio features must be (T, {da}), got {oa.shape}")
    return _AudioMarginal(model).loglik(model, oa)


def audio_log_likelihood(model: AvHmm, sequences: Sequence[np.ndarray]) -> float:
    """Total ``log p(O_a | model)`` of audio-only sequences ``(T_i, Da)`` under the audio marginal HMM."""
    marginal = _AudioMarginal(model)
    total = 0.0
    for i, s in enumerate(sequences):
        s = np.asarray(s, dtype=np.float64)
        if s.ndim != 2 or s.shape[1] != model.n_audio:
            raise InvalidFeaturesError(f"audio sequence {i} must be (T, {model.n_audio}), got {s.shape}")
        if len(s):
            log_b = logsumexp(marginal.loglik(model, s), axis=2)
            total += log_forward(model.log_startprob, model.log_transmat, log_b)[1]
    return total


def _log_prior(model: AvHmm, prior: AvHmm, config: AdaptConfig) -> float:
    """Log MAP prior of ``model``'s audio means and weights (up to a constant). An infinite relevance is a point
    mass at the prior, which the M-step keeps: its term is that constant (0), not ``inf * 0``."""
    n, m, _ = model.means.shape
    da = model.n_audio
    total = 0.0
    if np.isfinite(config.relevance):
        diff = (model.means[:, :, :da] - prior.means[:, :, :da]).reshape(n * m, da)
        z = np.linalg.solve(_audio_chol(prior), diff[..., None])[..., 0]  # L^-1 (mu - mu0): same covariances
        total -= 0.5 * config.relevance * float(np.sum(z**2))
    if config.weight_relevance is not None and np.isfinite(config.weight_relevance):
        with np.errstate(divide="ignore"):
            total += config.weight_relevance * float(np.sum(prior.weights * np.log(model.weights)))
    return total


def _check(sequences: Sequence[np.ndarray], da: int) -> list[np.ndarray]:
    out = []
    for i, s in enumerate(sequences):
        s = np.asarray(s, dtype=np.float64)
        if s.ndim != 2 or s.shape[1] != da:
            raise InvalidFeaturesError(f"adaptation sequence {i} must be (T, {da}), got {s.shape}")
        if not np.all(np.isfinite(s)):
            raise InvalidFeaturesError(f"adaptation sequence {i} contains NaN or inf")
        if len(s):
            out.append(s)
    return out


def _e_step(model: AvHmm, marginal: _AudioMarginal, seqs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, float]:
    """Occupancies ``(N, M)``, first-order sums ``(N, M, Da)`` and ``log p(O_a)``."""
    n, m, _ = model.means.shape
    da = model.n_audio
    occ = np.zeros((n, m))
    s1 = np.zeros((n, m, da))
    loglik = 0.0
    for s in seqs:
        logc = marginal.loglik(model, s)  # (T, N, M)
        log_b = logsumexp(logc, axis=2)
        gamma, ll, _, _ = forward_backward(model.log_startprob, model.log_transmat, log_b)
        with np.errstate(under="ignore"):
            resp = gamma[:, :, None] * np.exp(logc - log_b[:, :, None])  # (T, N, M)
        occ += resp.sum(axis=0)
        s1 += np.einsum("tnm,td->nmd", resp, s)
        loglik += ll
    return occ, s1, loglik


def map_adapt(model: AvHmm, sequences: Sequence[np.ndarray], *, config: AdaptConfig | None = None) -> AdaptResult:
    """Adapt ``model``'s audio means (and mixture weights) to audio-only ``sequences``
    (each ``(T_i, Da)``, the same features the model was trained on). Returns the adapted
    HMM (visual means, covariances and transitions unchanged) and the objective history."""
    config = config or AdaptConfig()
    da = model.n_audio
    seqs = _check(sequences, da)
    n_frames = int(sum(len(s) for s in seqs))
    if n_frames == 0:
        return AdaptResult(model=model, history=[], occupancy=np.zeros((model.n_states, model.n_mix)), n_frames=0)
    prior = model
    marginal = _AudioMarginal(prior)  # covariances are never adapted
    tau = config.relevance
    history: list[float] = []
    occ = None
    for it in range(config.n_iter + 1):
        occ, s1, loglik = _e_step(model, marginal, seqs)
        history.append((loglik + _log_prior(model, prior, config)) / n_frames)
        if it == config.n_iter or (len(history) > 1 and history[-1] - history[-2] < config.tol):
            break
        means = prior.means.copy()
        if np.isfinite(tau):  # an infinite prior weight keeps the means bit for bit (inf * mu0 / inf is NaN)
            means[:, :, :da] = (tau * prior.means[:, :, :da] + s1) / (tau + occ)[:, :, None]
        weights = prior.weights
        if config.weight_relevance is not None and np.isfinite(config.weight_relevance):
            tw = config.weight_relevance
            weights = (tw * prior.weights + occ) / (tw + occ.sum(axis=1, keepdims=True))
            weights = weights / weights.sum(axis=1, keepdims=True)
        model = AvHmm(
            startprob=model.startprob,
            transmat=model.transmat,
            weights=weights,
            means=means,
            covars=model.covars,
            covariance_type=model.covariance_type,
            n_audio=da,
        )
    return AdaptResult(model=model, history=history, occupancy=occ, n_frames=n_frames)
