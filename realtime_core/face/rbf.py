"""RBF mapping of control-point motion onto a head (paper 001 Sec. 3.5), for comparison with Sec. 5.

Paper 001 fits f(x) = sum_j w_j exp(-|x - S_j|^2 / r^2) by ridge regression,
E = |y - H w|^2 + lambda |w|^2, with r^2 the mean squared distance of the samples to their mean
and lambda chosen by generalised cross-validation (GCV). Here the samples are the control points
(3D positions on the head), so f is a spatial displacement field: with H = U S V^T,
w = V diag(s / (s^2 + lambda)) U^T y, the influence matrix is A = U diag(s^2 / (s^2 + lambda)) U^T and
GCV(lambda) = n |(I - A) Y|^2 / tr(I - A)^2, pooled over the training displacement fields Y
(the simple model's unit motions). Everything is linear in the control displacements, so the
head map is one matrix G = H_head V diag(s / (s^2 + lambda)) U^T of shape (n_head, n_simple).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError


@dataclass(frozen=True)
class RbfFit:
    """weights: (n_head, n_simple) dense map; lam: chosen regulariser; radius: Gaussian r (head units);
    gcv: (len(grid),) GCV score per candidate lambda."""

    weights: np.ndarray
    lam: float
    radius: float
    gcv: np.ndarray


def gcv_scores(h: np.ndarray, y: np.ndarray, lambdas: np.ndarray) -> np.ndarray:
    """GCV score per lambda (len(lambdas),) for design matrix h (n, m) and targets y (n, c)."""
    u, s, _ = np.linalg.svd(h, full_matrices=False)
    uty = u.T @ y
    resid0 = float((y**2).sum() - (uty**2).sum())  # part of y outside range(H)
    n = h.shape[0]
    out = np.empty(len(lambdas))
    for i, lam in enumerate(lambdas):
        f = s**2 / (s**2 + lam)
        r = resid0 + float((((1 - f)[:, None] * uty) ** 2).sum())
        tr = n - f.sum()
        out[i] = n * r / max(tr, 1e-300) ** 2
    return out


def rbf_map(
    head_vertices: np.ndarray,
    control_points: np.ndarray,
    training: np.ndarray,
    *,
    radius: float | None = None,
    lambdas: np.ndarray | None = None,
) -> RbfFit:
    """Gaussian-RBF map from control-point displacements to head-vertex displacements.

    head_vertices (n_h, 3), control_points (n_s, 3) (head units); training (n_s, c): displacement
    components used to choose lambda by GCV (e.g. the unit motions, 3 columns per unit);
    radius: Gaussian r in head units (default: paper 001, r^2 = mean |x - mean|^2 of the controls);
    lambdas: candidate regularisers (default 1e-8..1e2, log-spaced).
    """
    c = np.asarray(control_points, dtype=np.float64)
    y = np.asarray(training, dtype=np.float64)
    if y.ndim != 2 or y.shape[0] != len(c):
        raise ConfigError(f"training must be ({len(c)}, c), got {y.shape}")
    r2 = float(((c - c.mean(0)) ** 2).sum(1).mean()) if radius is None else float(radius) ** 2
    if not r2 > 0:
        raise ConfigError("RBF radius must be > 0")
    grid = np.logspace(-8, 2, 41) if lambdas is None else np.asarray(lambdas, dtype=np.float64)

    def design(x: np.ndarray) -> np.ndarray:
        d2 = ((x[:, None, :] - c[None, :, :]) ** 2).sum(-1)
        return np.exp(-d2 / r2)

    h = design(c)
    scores = gcv_scores(h, y, grid)
    lam = float(grid[int(np.argmin(scores))])
    u, s, vt = np.linalg.svd(h, full_matrices=False)
    core = vt.T @ np.diag(s / (s**2 + lam)) @ u.T  # (n_s, n_s): y -> w
    hv = np.asarray(head_vertices, dtype=np.float64)
    weights = np.empty((len(hv), len(c)))
    for lo in range(0, len(hv), 4096):  # bounded memory for big heads
        weights[lo : lo + 4096] = design(hv[lo : lo + 4096]) @ core
    return RbfFit(weights=weights, lam=lam, radius=float(np.sqrt(r2)), gcv=scores)
