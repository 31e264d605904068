"""EM-PCA (Roweis 1998; seed 001 Sec. 3.6): the leading principal subspace without a covariance.

Theory of operation
-------------------
Motion frames ``y_t`` (rows of ``Y``, ``(n, p)``) are modelled as ``y_t = mean + C x_t`` with a
``(p, k)`` loading matrix ``C`` and ``k``-dimensional latent coordinates ``x_t``. Alternating

    E-step:  X = (C^T C)^-1 C^T Y_c        (coordinates of every frame in the current subspace)
    M-step:  C = Y_c X^T (X X^T)^-1        (the subspace that best explains those coordinates)

(``Y_c`` the centred data, one column per frame) converges to a ``C`` spanning the leading
``k``-dimensional principal subspace. Each step costs ``O(n p k)`` and never forms the
``(p, p)`` covariance, which is why the paper uses it for high-dimensional retargeted frames.

``C`` is only a basis of the subspace; the principal axes inside it and their variances come from
an eigen-decomposition of the small ``(k, k)`` covariance of the projected data, which also
orders them. The number of components kept is the smallest ``k`` whose components explain at
least ``explained`` of the total variance (``trace`` of the covariance = mean squared norm of the
centred frames, computed without the covariance too).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError, InvalidFeaturesError


@dataclass(frozen=True, kw_only=True)
class EmPcaConfig:
    """max_components: size of the subspace EM-PCA estimates (the kept ``k`` is <= this);
    explained: fraction of the total variance the kept components must explain (0 < e <= 1);
    max_iterations / tolerance: stop when the subspace moves less than ``tolerance`` (largest
    sine of the principal angles between successive subspaces); seed: the random initial ``C``."""

    max_components: int = 24
    explained: float = 0.99
    max_iterations: int = 500
    tolerance: float = 1e-7
    seed: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.max_components, int) or self.max_components < 1:
            raise ConfigError(f"max_components must be an integer >= 1, got {self.max_components!r}")
        if not 0.0 < self.explained <= 1.0:
            raise ConfigError(f"explained must be in (0, 1], got {self.explained!r}")
        if self.max_iterations < 1 or not self.tolerance > 0:
            raise ConfigError("max_iterations must be >= 1 and tolerance > 0")


@dataclass(frozen=True, kw_only=True)
class Pca:
    """A fitted PCA: ``y ~= mean + coefficients @ components``.

    mean: (p,) float64; components: (k, p) float64 orthonormal rows, by decreasing variance;
    variances: (k,) float64 variance of each component's coefficient; total_variance: of the
    data (trace of its covariance); iterations: EM iterations used.
    """

    mean: np.ndarray
    components: np.ndarray
    variances: np.ndarray
    total_variance: float
    iterations: int = 0

    @property
    def n_components(self) -> int:
        return int(self.components.shape[0])

    @property
    def explained_ratio(self) -> np.ndarray:
        """(k,) cumulative fraction of the total variance explained by the first 1..k components."""
        return np.cumsum(self.variances) / max(self.total_variance, 1e-300)

    def transform(self, y: np.ndarray) -> np.ndarray:
        """(n, p) frames -> (n, k) coefficients."""
        return (np.asarray(y, dtype=np.float64) - self.mean) @ self.components.T

    def inverse_transform(self, x: np.ndarray) -> np.ndarray:
        """(n, k) coefficients -> (n, p) frames."""
        return np.asarray(x, dtype=np.float64) @ self.components + self.mean

    def truncated(self, k: int) -> Pca:
        """The first ``k`` components."""
        return Pca(
            mean=self.mean,
            components=self.components[:k],
            variances=self.variances[:k],
            total_variance=self.total_variance,
            iterations=self.iterations,
        )


def _check(y: np.ndarray) -> np.ndarray:
    y = np.asarray(y, dtype=np.float64)
    if y.ndim != 2 or y.shape[0] < 2 or y.shape[1] < 1:
        raise InvalidFeaturesError(f"EM-PCA needs (n_frames >= 2, n_dims >= 1) data, got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise InvalidFeaturesError("EM-PCA data contain NaN or infinite values")
    return y


def em_subspace(yc: np.ndarray, k: int, config: EmPcaConfig) -> tuple[np.ndarray, int]:
    """Roweis's EM iterations on centred frames ``yc`` (n, p): an orthonormal (p, k) basis of the
    leading k-dimensional principal subspace and the number of iterations used."""
    p = yc.shape[1]
    rng = np.random.default_rng(config.seed)
    c = rng.standard_normal((p, k))
    q_old = np.linalg.qr(c)[0]
    it = 0
    for it in range(1, config.max_iterations + 1):  # noqa: B007 - the count is returned after the loop
        x = np.linalg.solve(c.T @ c, c.T @ yc.T)  # E-step: (k, n)
        c = (yc.T @ x.T) @ np.linalg.inv(x @ x.T)  # M-step: (p, k)
        q = np.linalg.qr(c)[0]
        # largest sine of the principal angles between the old and the new subspace
        s = np.linalg.svd(q_old.T @ q, compute_uv=False)
        q_old = q
        if np.sqrt(max(0.0, 1.0 - float(s.min()) ** 2)) < config.tolerance:
            break
    return q_old, it


def fit_empca(y: np.ndarray, config: EmPcaConfig = EmPcaConfig()) -> Pca:
    """PCA of frames ``y`` (n_frames, n_dims) by EM-PCA; keeps the fewest components explaining
    ``config.explained`` of the variance (at most ``config.max_components``)."""
    y = _check(y)
    mean = y.mean(axis=0)
    yc = y - mean
    n, p = yc.shape
    total = float(np.einsum("ij,ij->", yc, yc) / (n - 1))
    k = min(config.max_components, p, n - 1)
    q, iterations = em_subspace(yc, k, config)
    # principal axes inside the subspace: eigenvectors of the (k, k) covariance of the projections
    z = yc @ q
    evals, evecs = np.linalg.eigh(z.T @ z / (n - 1))
    order = np.argsort(evals)[::-1]
    evals, evecs = np.maximum(evals[order], 0.0), evecs[:, order]
    components = (q @ evecs).T
    # a deterministic sign per axis (largest-magnitude entry positive) so refits compare equal
    signs = np.sign(components[np.arange(k), np.argmax(np.abs(components), axis=1)])
    components *= np.where(signs == 0, 1.0, signs)[:, None]
    full = Pca(mean=mean, components=components, variances=evals, total_variance=total, iterations=iterations)
    ratio = full.explained_ratio
    keep = int(np.searchsorted(ratio, config.explained - 1e-12) + 1)
    return full.truncated(min(keep, k))
