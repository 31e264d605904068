"""Motion Units (paper 002, Sec. IV-A and eq. 1-2): PCA of facial deformation vectors.

A deformation vector ``d (D,)`` is the concatenation of the landmark displacements of one frame
relative to the neutral face (``D = 3 x n_landmarks``, IOD units, pose-free face frame).

*Utterance MUs* ``M_0``: the mean ``m_00 = E[d]`` and the first ``A_0`` eigenvectors of the
covariance of the neutral-expression deformations ``D_0``; a frame's Utterance MU parameters
(UMUPs) are ``c_0 = M_0^T (d - m_00)``.

*Expression MUs* ``M_k`` (eq. 1): PCA of what ``M_0`` cannot represent in the deformations
``D_k`` recorded under expression ``k``. Eq. 1 as printed projects ``d`` itself; we project
``d - m_00`` (the residual of the utterance reconstruction) so that eq. 2 reconstructs the
training frames exactly when all units are kept.

Eq. 2 with an intensity: ``d = m_00 + M_0 c_0 + alpha (m_k0 + M_k c_k)``. The paper's
``alpha_k`` is 0 or 1 (one expression at a time); ``alpha in [0, 1]`` lets an expression ease in.

The PCA is the paper's: eigen-decomposition of the sample covariance (``scipy.linalg.eigh``);
the tests check it against an SVD of the centred data. Eigenvector signs are fixed (largest
absolute component positive) so that refits of the same data give the same units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import eigh

from realtime_core.errors import ConfigError, InvalidFeaturesError


@dataclass(frozen=True, kw_only=True, eq=False)
class MotionUnits:
    """One PCA basis of deformations.

    mean: ``(D,)`` float64 ``m_0`` (the mean deformation, IOD); units: ``(A, D)`` float64 orthonormal
    rows ``m_1..m_A``; eigenvalues: ``(min(N-1, D),)`` the full descending covariance spectrum of the
    training data (``eigenvalues[:A]`` belong to the kept units), so the variance report needs no refit.
    """

    mean: np.ndarray
    units: np.ndarray
    eigenvalues: np.ndarray

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=np.float64)
        units = np.asarray(self.units, dtype=np.float64)
        ev = np.asarray(self.eigenvalues, dtype=np.float64)
        if mean.ndim != 1 or units.ndim != 2 or units.shape[1] != mean.size:
            raise ConfigError(f"MotionUnits: mean (D,) and units (A, D) expected, got {mean.shape}, {units.shape}")
        if ev.ndim != 1 or ev.size < units.shape[0]:
            raise ConfigError(f"MotionUnits: {ev.size} eigenvalues for {units.shape[0]} units")
        if not (np.isfinite(mean).all() and np.isfinite(units).all() and np.isfinite(ev).all()):
            raise ConfigError("MotionUnits: non-finite values")
        if units.shape[0] and not np.allclose(units @ units.T, np.eye(units.shape[0]), atol=1e-6):
            raise ConfigError("MotionUnits: units are not orthonormal")
        for name, arr in (("mean", mean), ("units", units), ("eigenvalues", ev)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n_units(self) -> int:
        return int(self.units.shape[0])

    @property
    def dim(self) -> int:
        return int(self.mean.size)

    def explained(self) -> np.ndarray:
        """``(len(eigenvalues),)`` cumulative fraction of the training variance kept by 1, 2, ... units."""
        total = self.eigenvalues.sum()
        return np.cumsum(self.eigenvalues) / total if total > 0 else np.ones_like(self.eigenvalues)

    def _rows(self, d: np.ndarray) -> np.ndarray:
        x = np.asarray(d, dtype=np.float64)
        if x.shape[-1] != self.dim:
            raise InvalidFeaturesError(f"deformations must be (..., {self.dim}), got {x.shape}")
        return x

    def project(self, d: np.ndarray) -> np.ndarray:
        """MU parameters of deformations: ``(..., D) -> (..., A)``, ``c = M^T (d - m_0)``."""
        return (self._rows(d) - self.mean) @ self.units.T

    def reconstruct(self, c: np.ndarray) -> np.ndarray:
        """Deformations from parameters: ``(..., A) -> (..., D)``, ``d = m_0 + M c``."""
        c = np.asarray(c, dtype=np.float64)
        if c.shape[-1] != self.n_units:
            raise InvalidFeaturesError(f"MU parameters must be (..., {self.n_units}), got {c.shape}")
        return self.mean + c @ self.units

    def residual(self, d: np.ndarray) -> np.ndarray:
        """Eq. 1: what these units cannot represent, ``(..., D)``."""
        x = self._rows(d)
        return x - self.reconstruct(self.project(x))

    def truncated(self, n_units: int) -> MotionUnits:
        """The same basis keeping only the first ``n_units``."""
        if not 0 <= n_units <= self.n_units:
            raise ConfigError(f"n_units must be in 0..{self.n_units}, got {n_units}")
        return MotionUnits(mean=self.mean, units=self.units[:n_units], eigenvalues=self.eigenvalues)


def fit_motion_units(
    d: np.ndarray, *, n_units: int | None = None, min_variance: float = 0.97, max_units: int = 64
) -> MotionUnits:
    """PCA of deformations ``d (N, D)``: the mean and the leading covariance eigenvectors.

    n_units: how many to keep; None = the fewest whose cumulative variance reaches ``min_variance``
    (capped at ``max_units``).
    """
    x = np.asarray(d, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] < 2 or x.shape[1] < 1:
        raise InvalidFeaturesError(f"deformations must be (N >= 2, D >= 1), got {x.shape}")
    if not np.isfinite(x).all():
        raise InvalidFeaturesError("deformations contain NaN or inf")
    if not 0 < min_variance <= 1:
        raise ConfigError(f"min_variance must be in (0, 1], got {min_variance}")
    mean = x.mean(axis=0)
    xc = x - mean
    cov = xc.T @ xc / (x.shape[0] - 1)  # Lambda_0 of the paper (unbiased)
    w, v = eigh(cov)
    order = np.argsort(w)[::-1]
    w, v = np.maximum(w[order], 0.0), v[:, order]
    k = min(x.shape[0] - 1, x.shape[1])
    w, v = w[:k], v[:, :k]
    if n_units is None:
        cum = np.cumsum(w) / w.sum() if w.sum() > 0 else np.ones_like(w)
        n_units = int(min(np.searchsorted(cum, min_variance - 1e-12) + 1, max_units, k))
    if not 0 <= n_units <= k:
        raise ConfigError(
            f"n_units must be in 0..{k} for {x.shape[0]} samples of dimension {x.shape[1]}, got {n_units}"
        )
    units = v[:, :n_units].T.copy()
    # Fix each eigenvector's sign: its largest-magnitude component is positive.
    flip = np.sign(units[np.arange(n_units), np.abs(units).argmax(axis=1)])
    units *= np.where(flip == 0, 1.0, flip)[:, None]
    return MotionUnits(mean=mean, units=units, eigenvalues=w)


@dataclass(frozen=True, kw_only=True, eq=False)
class ExpressionUnits:
    """Expression MUs of one expression (eq. 1): name; basis: PCA of the residuals (``basis.mean`` is
    ``m_k0``, ``basis.units`` are ``m_k1..m_kA``)."""

    name: str
    basis: MotionUnits


def fit_expression_units(utterance: MotionUnits, d_k: np.ndarray, *, name: str, n_units: int = 2) -> ExpressionUnits:
    """Eq. 1 then PCA: the expression ``name``'s units from its deformations ``d_k (N_k, D)``."""
    if not name or not name.isidentifier():
        raise ConfigError(f"expression name must be an identifier, got {name!r}")
    return ExpressionUnits(name=name, basis=fit_motion_units(utterance.residual(d_k), n_units=n_units))


def analyse(
    utterance: MotionUnits, expression: ExpressionUnits | None, d: np.ndarray, alpha: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Deformations ``(..., D)`` -> ``(UMUPs (..., A_0), EMUPs (..., A_k))`` (eq. 4's projections; no
    expression or ``alpha == 0``: EMUPs are empty / zero)."""
    c0 = utterance.project(d)
    if expression is None:
        return c0, np.zeros((*c0.shape[:-1], 0))
    if alpha == 0:
        return c0, np.zeros((*c0.shape[:-1], expression.basis.n_units))
    r = np.asarray(d, dtype=np.float64) - utterance.reconstruct(c0)
    return c0, expression.basis.project(r / alpha)


def compose(
    utterance: MotionUnits,
    umup: np.ndarray,
    expression: ExpressionUnits | None = None,
    emup: np.ndarray | None = None,
    alpha: float | np.ndarray = 1.0,
) -> np.ndarray:
    """Eq. 2: ``d = m_00 + M_0 c_0 + alpha (m_k0 + M_k c_k)`` -> ``(..., D)``; alpha scalar or ``(...,)``."""
    d = utterance.reconstruct(umup)
    if expression is None:
        return d
    c = np.zeros((*np.shape(umup)[:-1], expression.basis.n_units)) if emup is None else emup
    a = np.asarray(alpha, dtype=np.float64)
    return d + a[..., None] * expression.basis.reconstruct(c)
