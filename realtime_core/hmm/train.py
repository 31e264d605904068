"""Baum-Welch training of the audio-visual HMM over many sequences (paper Sec. 4.1).

Theory of operation
-------------------
*Initialisation.* The joint data are whitened (global PCA whitening) and clustered by
k-means into N state clusters; each state's frames are clustered again into M
sub-clusters that become its mixture components. The transition matrix and start
probabilities are counted from the state-cluster label sequences. This gives every
state a compact, distinct region of the joint space before EM starts.

*EM with a prior (MAP-EM).* A full 81-dim covariance has 3,321 free parameters; a
component that owns fewer frames than dimensions would become singular. Each
covariance therefore has an inverse-Wishart prior with scale ``Psi = r * s * diag(var)``
(``r = covar_prior_weight`` pseudo-frames, ``s = covar_prior_scale`` times the global
per-dimension variance), so the M-step is ``Sigma = (S + Psi) / (n + r)``, positive
definite for any n. Start, transition and mixture weights get a Dirichlet pseudo-count
``pseudo_count``. The objective is the log-likelihood plus these log-priors; EM never
lowers it, and :class:`TrainResult.history` records it per frame so tests can assert that.

*Exact EM vs hmmlearn.* By default covariances are re-estimated around the *new* means
(exact EM). hmmlearn's GMMHMM centres them on the *previous* means;
``centering="previous"`` reproduces that for cross-checking (not exact EM: the objective
may then fall slightly).

*Cost.* Per iteration, per component: one triangular solve over all frames (E-step)
and one weighted ``X^T X`` (M-step), both BLAS level 3. Statistics are accumulated
around the global data mean to avoid cancellation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.cluster.vq
from scipy.special import logsumexp

from realtime_core.errors import ConfigError, InvalidFeaturesError
from realtime_core.hmm.kernels import expected_transitions, forward_backward
from realtime_core.hmm.model import AvHmm, component_loglik

ProgressFn = Callable[[int, float, AvHmm], None]
"""Called after each E-step with (iteration index, objective per frame, the model it scored):
for progress bars and checkpoints (the caller decides what to do; this module does no I/O)."""


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """n_states N, n_mix M; covariance_type "full" | "diag".
    n_iter: maximum EM iterations; tol: stop when the objective gains less than this per frame.
    covar_prior_weight r (pseudo-frames) and covar_prior_scale s: inverse-Wishart prior
    ``Psi = r s diag(global var)``. pseudo_count: Dirichlet pseudo-count on start,
    transition and mixture weights. centering: "exact" (EM) or "previous" (hmmlearn).
    seed: k-means initialisation. kmeans_max_frames: frames sampled for k-means;
    kmeans_restarts: k-means++ runs, the lowest distortion wins. chunk_frames: E-step chunk.
    resp_floor: frames with a component responsibility below this are left out of its
    scatter matrix (0 = exact to the last bit, as for the hmmlearn cross-check).
    """

    n_states: int = 28
    n_mix: int = 5
    covariance_type: str = "full"
    n_iter: int = 30
    tol: float = 1e-3
    covar_prior_weight: float = 2.0
    covar_prior_scale: float = 0.05
    pseudo_count: float = 1e-2
    centering: str = "exact"
    seed: int = 0
    kmeans_max_frames: int = 30000
    kmeans_restarts: int = 5
    chunk_frames: int = 20000
    resp_floor: float = 1e-8

    def __post_init__(self) -> None:
        if self.n_states < 1 or self.n_mix < 1:
            raise ConfigError(f"n_states and n_mix must be >= 1, got {self.n_states}, {self.n_mix}")
        if self.covariance_type not in ("full", "diag"):
            raise ConfigError(f"covariance_type must be 'full' or 'diag', got {self.covariance_type!r}")
        if self.centering not in ("exact", "previous"):
            raise ConfigError(f"centering must be 'exact' or 'previous', got {self.centering!r}")
        if self.covar_prior_weight < 0 or self.covar_prior_scale < 0 or self.pseudo_count < 0:
            raise ConfigError("priors must be >= 0")
        if self.n_iter < 0 or self.tol < 0:
            raise ConfigError("n_iter and tol must be >= 0")


@dataclass(frozen=True)
class TrainResult:
    """model: the trained HMM; history: objective per frame before each M-step (and at the
    end), so ``history[i + 1] >= history[i]`` for exact EM; converged: tol reached."""

    model: AvHmm
    history: list[float] = field(default_factory=list)
    converged: bool = False


def _check_sequences(sequences: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    if len(sequences) == 0:
        raise InvalidFeaturesError("no training sequences")
    d = np.asarray(sequences[0]).shape[-1]
    for i, s in enumerate(sequences):
        s = np.asarray(s)
        if s.ndim != 2 or s.shape[1] != d or s.shape[0] < 1:
            raise InvalidFeaturesError(f"sequence {i} must be (T >= 1, {d}), got {s.shape}")
        if not np.all(np.isfinite(s)):
            raise InvalidFeaturesError(f"sequence {i} contains NaN or inf")
    lengths = np.array([len(s) for s in sequences])
    return np.concatenate([np.asarray(s, dtype=np.float64) for s in sequences]), lengths


def _normalise_rows(a: np.ndarray) -> np.ndarray:
    s = a.sum(axis=-1, keepdims=True)
    return np.where(s > 0, a / np.where(s > 0, s, 1.0), 1.0 / a.shape[-1])


def _prior_psi(x: np.ndarray, config: TrainConfig) -> np.ndarray:
    """Inverse-Wishart scale diagonal ``r * s * var``: ``(D,)``."""
    var = x.var(axis=0)
    var = np.where(var > 0, var, 1.0)
    return config.covar_prior_weight * config.covar_prior_scale * var


def _kmeans(data: np.ndarray, k: int, rng: np.random.Generator, restarts: int) -> np.ndarray:
    """k-means++ with restarts; the codebook with the lowest distortion, ``(k, D)``."""
    best: np.ndarray | None = None
    best_cost = np.inf
    for _ in range(max(restarts, 1)):
        book, _ = scipy.cluster.vq.kmeans2(data, k, minit="++", seed=rng, iter=30)
        _, dist = scipy.cluster.vq.vq(data, book)
        cost = float(np.sum(dist**2))
        if cost < best_cost:
            best, best_cost = book, cost
    assert best is not None  # at least one restart ran
    return best


def init_model(sequences: Sequence[np.ndarray], *, n_audio: int, config: TrainConfig) -> AvHmm:
    """k-means initialisation on whitened data. ``sequences``: list of ``(T_i, D)``."""
    x, lengths = _check_sequences(sequences)
    n, m = config.n_states, config.n_mix
    rng = np.random.default_rng(config.seed)
    mean = x.mean(axis=0)
    cov = np.cov(x, rowvar=False) + 1e-9 * np.eye(x.shape[1])
    evals, evecs = np.linalg.eigh(cov)
    whiten = evecs / np.sqrt(np.maximum(evals, 1e-12 * evals.max()))
    xw = (x - mean) @ whiten
    sample = (
        xw if len(xw) <= config.kmeans_max_frames else xw[rng.choice(len(xw), config.kmeans_max_frames, replace=False)]
    )
    if len(sample) < n * m:
        raise InvalidFeaturesError(f"{len(sample)} frames are too few for {n} states x {m} mixtures")
    centroids = _kmeans(sample, n, rng, config.kmeans_restarts)
    labels, _ = scipy.cluster.vq.vq(xw, centroids)
    psi = _prior_psi(x, config)
    r = config.covar_prior_weight
    d = x.shape[1]
    means = np.empty((n, m, d))
    covars = np.empty((n, m, d, d)) if config.covariance_type == "full" else np.empty((n, m, d))
    weights = np.empty((n, m))
    for j in range(n):
        xj = x[labels == j]
        if len(xj) < m:  # an empty state: borrow random frames so it starts somewhere sensible
            xj = x[rng.choice(len(x), max(m, 2 * m), replace=False)]
        if m > 1:
            xjw = (xj - mean) @ whiten
            sub, _ = scipy.cluster.vq.vq(xjw, _kmeans(xjw, m, rng, config.kmeans_restarts))
        else:
            sub = np.zeros(len(xj), dtype=int)
        for k in range(m):
            xk = xj[sub == k]
            if len(xk) == 0:
                xk = xj[rng.choice(len(xj), 1)]
            means[j, k] = xk.mean(axis=0)
            c = xk - means[j, k]
            if config.covariance_type == "full":
                covars[j, k] = (c.T @ c + np.diag(psi) + (1e-6 if r == 0 else 0.0) * np.eye(d)) / (
                    len(xk) + max(r, 1.0)
                )
            else:
                covars[j, k] = ((c**2).sum(axis=0) + psi + (1e-6 if r == 0 else 0.0)) / (len(xk) + max(r, 1.0))
            weights[j, k] = len(xk)
    weights = _normalise_rows(weights + 1e-3)
    # Transitions and starts counted from the label sequences (plus one).
    trans = np.ones((n, n))
    start = np.ones(n)
    pos = 0
    for length in lengths:
        lab = labels[pos : pos + length]
        start[lab[0]] += 1
        np.add.at(trans, (lab[:-1], lab[1:]), 1.0)
        pos += length
    return AvHmm(
        startprob=_normalise_rows(start),
        transmat=_normalise_rows(trans),
        weights=weights,
        means=means,
        covars=covars,
        covariance_type=config.covariance_type,
        n_audio=n_audio,
    )


def _log_prior(model: AvHmm, psi: np.ndarray, config: TrainConfig) -> float:
    """Log of the (unnormalised) priors at ``model``: inverse-Wishart + Dirichlet."""
    total = 0.0
    p = config.pseudo_count
    if p > 0:
        with np.errstate(divide="ignore"):
            total += p * (np.log(model.startprob).sum() + np.log(model.transmat).sum() + np.log(model.weights).sum())
    r = config.covar_prior_weight
    if r > 0:
        chol = model.chol  # (N, M, D, D)
        logdet = 2.0 * np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(axis=-1)  # (N, M)
        if model.covariance_type == "diag":
            trace = (psi / model.covars).sum(axis=-1)
        else:
            # tr(Psi Sigma^-1) = || L^-1 diag(sqrt psi) ||_F^2, by triangular solves.
            n, m, d, _ = chol.shape
            rhs = np.broadcast_to(np.diag(np.sqrt(psi)), (n * m, d, d))
            z = np.linalg.solve(chol.reshape(n * m, d, d), rhs)  # triangular L, small batch
            trace = (z**2).sum(axis=(-1, -2)).reshape(n, m)
        total += float(np.sum(-0.5 * r * logdet - 0.5 * trace))
    return total


def _e_step(
    model: AvHmm, x: np.ndarray, lengths: np.ndarray, config: TrainConfig, origin: np.ndarray
) -> tuple[dict[str, np.ndarray], float]:
    """Sufficient statistics and log-likelihood at ``model``."""
    n, m, d = model.means.shape
    c = n * m
    stats = {
        "start": np.zeros(n),
        "trans": np.zeros((n, n)),
        "n": np.zeros(c),
        "s1": np.zeros((c, d)),
        "s2": np.zeros((c, d, d)) if model.covariance_type == "full" else np.zeros((c, d)),
    }
    loglik = 0.0
    bounds = np.concatenate([[0], np.cumsum(lengths)])
    i = 0
    while i < len(lengths):
        # A chunk of whole sequences, about chunk_frames long.
        j = i + 1
        while j < len(lengths) and bounds[j + 1] - bounds[i] <= config.chunk_frames:
            j += 1
        xs = x[bounds[i] : bounds[j]]
        logc = component_loglik(model, xs)  # (T, N, M)
        log_b = logsumexp(logc, axis=2)  # (T, N)
        gamma = np.empty_like(log_b)
        for s in range(i, j):
            a, b = bounds[s] - bounds[i], bounds[s + 1] - bounds[i]
            g, ll, la, lb = forward_backward(model.log_startprob, model.log_transmat, log_b[a:b])
            gamma[a:b] = g
            stats["start"] += g[0]
            stats["trans"] += expected_transitions(la, lb, model.log_transmat, log_b[a:b], ll)
            loglik += ll
        with np.errstate(under="ignore"):
            resp = (gamma[:, :, None] * np.exp(logc - log_b[:, :, None])).reshape(len(xs), c)
        xc = xs - origin
        stats["n"] += resp.sum(axis=0)
        stats["s1"] += resp.T @ xc
        if model.covariance_type == "full":
            for k in range(c):
                rk = resp[:, k]
                # Each component owns a small share of the frames; the scatter skips the
                # frames whose responsibility is below resp_floor (their total weight is
                # negligible) which makes this, the costliest product, many times cheaper.
                idx = np.flatnonzero(rk > config.resp_floor) if config.resp_floor > 0 else np.arange(len(rk))
                if idx.size:
                    xk = xc[idx]
                    stats["s2"][k] += (xk * rk[idx, None]).T @ xk
        else:
            stats["s2"] += resp.T @ (xc**2)
        i = j
    return stats, loglik


def _m_step(
    model: AvHmm, stats: dict[str, np.ndarray], psi: np.ndarray, config: TrainConfig, origin: np.ndarray
) -> AvHmm:
    n, m, d = model.means.shape
    p = config.pseudo_count
    r = config.covar_prior_weight
    nk = stats["n"]
    safe = np.where(nk > 1e-10, nk, 1.0)
    old_mu = model.means.reshape(n * m, d) - origin
    mu = np.where((nk > 1e-10)[:, None], stats["s1"] / safe[:, None], old_mu)
    # Centre for the scatter: new means (exact EM) or previous means (hmmlearn).
    ctr = mu if config.centering == "exact" else old_mu
    if model.covariance_type == "full":
        s1c = stats["s1"][:, :, None] * ctr[:, None, :]
        scatter = stats["s2"] - s1c - np.swapaxes(s1c, 1, 2) + nk[:, None, None] * ctr[:, :, None] * ctr[:, None, :]
        scatter = 0.5 * (scatter + np.swapaxes(scatter, 1, 2))
        cov = (scatter + np.diag(psi)[None]) / (nk + r)[:, None, None]
        cov = cov.reshape(n, m, d, d)
    else:
        scatter = stats["s2"] - 2 * stats["s1"] * ctr + nk[:, None] * ctr**2
        cov = ((np.maximum(scatter, 0.0) + psi[None]) / (nk + r)[:, None]).reshape(n, m, d)
    weights = _normalise_rows(nk.reshape(n, m) + p)
    return AvHmm(
        startprob=_normalise_rows(stats["start"] + p),
        transmat=_normalise_rows(stats["trans"] + p),
        weights=weights,
        means=(mu + origin).reshape(n, m, d),
        covars=cov,
        covariance_type=model.covariance_type,
        n_audio=model.n_audio,
    )


def em_iteration(sequences: Sequence[np.ndarray], model: AvHmm, *, config: TrainConfig) -> tuple[AvHmm, float]:
    """One E-step and M-step. Returns ``(updated model, objective per frame at model)``."""
    x, lengths = _check_sequences(sequences)
    psi = _prior_psi(x, config)
    origin = x.mean(axis=0)
    stats, loglik = _e_step(model, x, lengths, config, origin)
    objective = (loglik + _log_prior(model, psi, config)) / len(x)
    return _m_step(model, stats, psi, config, origin), objective


def baum_welch(
    sequences: Sequence[np.ndarray],
    model: AvHmm,
    *,
    config: TrainConfig,
    progress: ProgressFn | None = None,
) -> TrainResult:
    """Run EM from ``model`` until the objective gains < ``tol`` per frame or ``n_iter``.

    ``sequences``: list of ``(T_i, D)`` joint observations ``[o_a; o_v]``.
    """
    x, lengths = _check_sequences(sequences)
    if x.shape[1] != model.n_dim:
        raise InvalidFeaturesError(f"sequences have {x.shape[1]} dims, model has {model.n_dim}")
    psi = _prior_psi(x, config)
    origin = x.mean(axis=0)
    total = float(len(x))
    history: list[float] = []
    converged = False
    for it in range(config.n_iter + 1):
        stats, loglik = _e_step(model, x, lengths, config, origin)
        history.append((loglik + _log_prior(model, psi, config)) / total)
        if progress is not None:
            progress(it, history[-1], model)
        if len(history) > 1 and history[-1] - history[-2] < config.tol:
            converged = True
            break
        if it == config.n_iter:
            break
        model = _m_step(model, stats, psi, config, origin)
    return TrainResult(model=model, history=history, converged=converged)


def fit(
    sequences: Sequence[np.ndarray],
    *,
    n_audio: int,
    config: TrainConfig,
    progress: ProgressFn | None = None,
) -> TrainResult:
    """k-means initialisation then Baum-Welch. ``sequences``: list of ``(T_i, D)``."""
    return baum_welch(
        sequences, init_model(sequences, n_audio=n_audio, config=config), config=config, progress=progress
    )


def log_likelihood(model: AvHmm, sequences: Sequence[np.ndarray]) -> float:
    """Total ``log P(O | model)`` over sequences of ``(T_i, D)``."""
    from realtime_core.hmm.kernels import log_forward

    total = 0.0
    for s in sequences:
        log_b = logsumexp(component_loglik(model, np.asarray(s, dtype=np.float64)), axis=2)
        total += log_forward(model.log_startprob, model.log_transmat, log_b)[1]
    return total
