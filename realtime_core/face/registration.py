"""Registration of a face model onto a head: similarity transform plus shape units.

Step 1 (Umeyama 1991): the similarity ``x -> s R x + t`` minimising the squared distance between
corresponding landmark points (k >= 3, not collinear), closed form through the SVD of their
cross-covariance. Step 2: the shape-unit weights sigma minimising
``|| s R (L0 + sum_j sigma_j SU_j[L]) + t - P ||^2 + ridge * |sigma|^2`` over the landmarks, which
is linear in sigma (the similarity is re-estimated once after the shapes are fitted). Step 3
(optional, our addition in place of the paper's manual slider adjustment): the landmark residuals
left after steps 1-2 are spread over the model by a Gaussian RBF warp (exact at the landmarks,
fading over ``warp_radius`` times the landmarks' RMS radius), so lips, corners and chin land on
their targets.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.face.model import FaceModel


@dataclass(frozen=True)
class Similarity:
    """x -> scale * rotation @ x + translation (rotation (3, 3) proper, translation (3,))."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform points (..., 3) -> (..., 3)."""
        return self.scale * np.asarray(points, dtype=np.float64) @ self.rotation.T + self.translation

    def apply_vectors(self, vectors: np.ndarray) -> np.ndarray:
        """Transform displacement vectors (..., 3) (no translation)."""
        return self.scale * np.asarray(vectors, dtype=np.float64) @ self.rotation.T

    def __iter__(self) -> Iterator[Any]:
        """Unpacks as ``scale, rotation, translation`` (``s * x @ R.T + t``)."""
        return iter((self.scale, self.rotation, self.translation))


def fit_similarity(src: np.ndarray, dst: np.ndarray) -> Similarity:
    """Least-squares similarity mapping ``src`` (k, 3) onto ``dst`` (k, 3) (Umeyama 1991): the one
    implementation (face registration here, head-pose removal in ``training.video``).

    Raises ConfigError for fewer than 3 points or (near-)collinear source points.
    """
    a = np.asarray(src, dtype=np.float64)
    b = np.asarray(dst, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 3:
        raise ConfigError(f"landmark arrays must both be (k, 3), got {a.shape} and {b.shape}")
    if len(a) < 3:
        raise ConfigError(f"need at least 3 landmarks for a similarity, got {len(a)}")
    ma, mb = a.mean(0), b.mean(0)
    ac, bc = a - ma, b - mb
    var_a = (ac**2).sum() / len(a)
    cov = bc.T @ ac / len(a)
    u, d, vt = np.linalg.svd(cov)
    sv = np.linalg.svd(ac, compute_uv=False)
    if sv[1] < 1e-9 * max(sv[0], 1e-300):
        raise ConfigError("landmarks are collinear: cannot fix the rotation")
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1.0
    r = u @ sign @ vt
    s = float(np.trace(np.diag(d) @ sign) / var_a)
    if not s > 0:
        raise ConfigError("degenerate landmark configuration (non-positive scale)")
    return Similarity(scale=s, rotation=r, translation=mb - s * r @ ma)


@dataclass(frozen=True)
class Registration:
    """Result of :func:`register`: the transform, shape weights and the placed model."""

    similarity: Similarity
    shape_weights: dict[str, float]
    model: FaceModel  # deformed by the shapes and transformed into head coordinates
    rms: float  # landmark RMS residual, head units


def register(
    model: FaceModel,
    model_landmarks: np.ndarray,
    head_points: np.ndarray,
    *,
    shape_units: tuple[str, ...] | None = None,
    ridge: float = 1e-3,
    warp_radius: float | None = None,
) -> Registration:
    """Place ``model`` on a head given landmark vertex indices (k,) of the model and their head points (k, 3).

    shape_units: the shape units to fit (default: all of the model's); ``ridge`` (dimensionless,
    relative to the landmark spread squared) keeps the weights small when landmarks underdetermine
    them; ``warp_radius`` (None = no warp) enables step 3. Returns the placed model (neutral =
    shaped, warped and transformed; units rotated and scaled, not adapted to the shape change).
    """
    idx = np.asarray(model_landmarks, dtype=np.int64)
    p = np.asarray(head_points, dtype=np.float64)
    if p.shape != (len(idx), 3):
        raise ConfigError(f"head_points must be ({len(idx)}, 3), got {p.shape}")
    if idx.size and (idx.min() < 0 or idx.max() >= model.n_vertices):
        raise ConfigError("model landmark index out of range")
    names = tuple(model.shape_units) if shape_units is None else tuple(shape_units)
    for n in names:
        if n not in model.shape_units:
            raise ConfigError(f"unknown shape unit {n!r}")
    base = model.vertices[idx]
    sim = fit_similarity(base, p)
    weights = np.zeros(len(names))
    if names:
        # Work in model coordinates: pull the head landmarks back through the similarity.
        for _ in range(2):
            target = (p - sim.translation) @ sim.rotation / sim.scale
            a = np.stack([model.shape_units[n][idx].reshape(-1) for n in names], axis=1)  # (3k, j)
            spread = float(((base - base.mean(0)) ** 2).sum())
            lhs = a.T @ a + ridge * spread * np.eye(len(names))
            weights = np.linalg.solve(lhs, a.T @ (target - base).reshape(-1))
            shaped = base + (a @ weights).reshape(-1, 3)
            sim = fit_similarity(shaped, p)
    sw = {n: float(w) for n, w in zip(names, weights)}
    shaped = model.deform(shape=sw)
    if warp_radius is not None:
        if not warp_radius > 0:
            raise ConfigError(f"warp_radius must be > 0, got {warp_radius}")
        target = (p - sim.translation) @ sim.rotation / sim.scale
        resid = target - shaped[idx]  # (k, 3) model units
        c = shaped[idx]
        r2 = (warp_radius**2) * float(((c - c.mean(0)) ** 2).sum(1).mean())
        k_ll = np.exp(-((c[:, None] - c[None]) ** 2).sum(-1) / r2)
        coef = np.linalg.solve(k_ll + 1e-9 * np.eye(len(c)), resid)
        k_vl = np.exp(-((shaped[:, None] - c[None]) ** 2).sum(-1) / r2)
        shaped = shaped + k_vl @ coef
    shaped_model = model.with_neutral(shaped)
    placed = shaped_model.transformed(sim.scale, sim.rotation, sim.translation)
    rms = float(np.sqrt(((placed.vertices[idx] - p) ** 2).sum(1).mean()))
    return Registration(similarity=sim, shape_weights=sw, model=placed, rms=rms)
