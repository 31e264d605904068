"""Keyframe (morph-target) weights by least squares, and heads animated by their own morph targets.

Paper 002 Sec. IV (eq. 3-4): a face animated by P keyframes kappa_1..kappa_P (here: a head's own
morph targets) is driven from another motion representation by finding, in a *reference* face, the
keyframes' semantic correspondents kappa'_i (same name, e.g. ARKit ``jawOpen``) and solving

    b = argmin_b || K' b - s ||^2,      K' = [kappa'_1 ... kappa'_P]   (eq. 4: (K'^T K')^-1 K'^T s)

for each reference shape s (a displacement of the reference face). We add the bounds every engine
puts on morph weights (``lo <= b <= hi``, default [0, 1]) and a small ridge so keyframes that the
motion does not need (eyes, brows) stay at 0 and duplicates share their weight. The reference
motion is linear in some source coordinates x (ARKit weights computed from the four mouth
parameters, or Motion Unit parameters): s = A x, so everything but a P-dimensional bounded
quadratic program is precomputed:

    b(x) = argmin_{lo <= b <= hi} 1/2 b^T H b - b^T (C x),   H = K'^T K' + ridge I,  C = K'^T A.

:class:`MorphRig` applies b to the head's own targets; it has the interface the renderer, the
exporters and the server's sessions use for a :class:`realtime_core.face.Rig` (``neutral``,
``triangles``, ``moving``, ``displacements(params)``, ``deformed(params)``, ``meta``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from realtime_core.errors import ConfigError


@dataclass(frozen=True)
class KeyframeMap:
    """Source coordinates x (k,) -> keyframe weights b (P,) (paper 002 eq. 4 with bounds).

    gram: (P, P) K'^T K' (+ ridge); cross: (P, k) K'^T A; lo, hi: weight bounds.
    Build it with :meth:`from_reference`."""

    gram: np.ndarray
    cross: np.ndarray
    lo: float = 0.0
    hi: float = 1.0
    # Set in __post_init__: the Cholesky factor of the Gram matrix.
    _chol: tuple[np.ndarray, bool] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        g = np.asarray(self.gram, dtype=np.float64)
        c = np.asarray(self.cross, dtype=np.float64)
        if g.ndim != 2 or g.shape[0] != g.shape[1] or g.shape[0] == 0:
            raise ConfigError(f"keyframe gram must be (P, P) with P > 0, got {g.shape}")
        if c.ndim != 2 or c.shape[0] != g.shape[0]:
            raise ConfigError(f"keyframe cross term must be ({g.shape[0]}, k), got {c.shape}")
        if not self.lo < self.hi:
            raise ConfigError(f"weight bounds must satisfy lo < hi, got [{self.lo}, {self.hi}]")
        object.__setattr__(self, "gram", g)
        object.__setattr__(self, "cross", c)
        object.__setattr__(self, "_chol", cho_factor(g, lower=False))  # upper: the compiled kernel reads U

    @property
    def n_keyframes(self) -> int:
        return int(self.gram.shape[0])

    @classmethod
    def from_reference(
        cls,
        keyframes: np.ndarray,
        source: np.ndarray,
        *,
        ridge: float = 1e-5,
        lo: float = 0.0,
        hi: float = 1.0,
    ) -> KeyframeMap:
        """keyframes: (P, d) the correspondents kappa'_i as flat reference displacements; source:
        (k, d) the reference displacement per unit of each source coordinate (the columns of A).
        ridge: relative to the mean diagonal of K'^T K' (keeps the normal equations definite)."""
        kf = np.asarray(keyframes, dtype=np.float64)
        a = np.asarray(source, dtype=np.float64)
        if kf.ndim != 2 or a.ndim != 2 or kf.shape[1] != a.shape[1]:
            raise ConfigError(f"keyframes (P, d) and source (k, d) must share d, got {kf.shape} and {a.shape}")
        g = kf @ kf.T
        scale = float(np.mean(np.diag(g))) if g.size else 1.0
        if not scale > 0:
            raise ConfigError("every keyframe correspondent is zero: nothing to solve for")
        g = g + ridge * scale * np.eye(len(g))
        return cls(gram=g, cross=kf @ a.T, lo=lo, hi=hi)

    def unbounded(self, x: np.ndarray) -> np.ndarray:
        """Eq. 4 without bounds: (..., k) -> (..., P)."""
        rhs = np.asarray(x, dtype=np.float64) @ self.cross.T
        return cho_solve(self._chol, rhs.reshape(-1, self.n_keyframes).T).T.reshape(rhs.shape)

    def weights(self, x: np.ndarray, *, iterations: int = 200, tol: float = 1e-9, kernel: str = "numba") -> np.ndarray:
        """Bounded eq. 4: (..., k) source coordinates -> (..., P) float64 weights in [lo, hi].

        An active-set solve of the box-constrained convex QP (exact once the active set is right;
        starts from the clipped unbounded solution, a few steps per frame). kernel: "numba" (the
        solve compiled, :mod:`realtime_core.face.compiled`) or "numpy" (the reference)."""
        if kernel not in ("numba", "numpy"):
            raise ConfigError(f"kernel must be 'numba' or 'numpy', got {kernel!r}")
        x = np.asarray(x, dtype=np.float64)
        if kernel == "numba":
            # The whole frame (right-hand side, unbounded start, active set) in one compiled call.
            from realtime_core.face.compiled import keyframe_weights  # numba's import is paid only here

            chol, g = self._chol[0], self.gram
            if x.ndim == 1:  # one frame (a live vertex viewer's): the kernel's own result, no batch wrapper
                return keyframe_weights(np.ascontiguousarray(x), self.cross, chol, g, self.lo, self.hi, iterations, tol)
            rows = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
            out = np.empty((len(rows), self.n_keyframes))
            for i, row in enumerate(rows):
                out[i] = keyframe_weights(row, self.cross, chol, g, self.lo, self.hi, iterations, tol)
            return out.reshape((*x.shape[:-1], self.n_keyframes))
        rhs = (x @ self.cross.T).reshape(-1, self.n_keyframes)
        out = np.empty_like(rhs)
        g = self.gram
        for i, f in enumerate(rhs):
            out[i] = _box_qp(g, f, self.lo, self.hi, cho_solve(self._chol, f), iterations, tol)
        return out.reshape((*x.shape[:-1], self.n_keyframes))

    def residual(self, keyframes: np.ndarray, source: np.ndarray, x: np.ndarray) -> float:
        """Relative residual ||K' b(x) - A x|| / ||A x|| (how well the keyframes reproduce a motion)."""
        s = np.asarray(x, dtype=np.float64) @ np.asarray(source, dtype=np.float64)
        fit = self.weights(x) @ np.asarray(keyframes, dtype=np.float64)
        return float(np.linalg.norm(fit - s) / max(float(np.linalg.norm(s)), 1e-300))


def _box_qp(
    g: np.ndarray, f: np.ndarray, lo: float, hi: float, start: np.ndarray, iterations: int, tol: float
) -> np.ndarray:
    """min 1/2 b^T g b - f^T b subject to lo <= b <= hi (g positive definite, small P).

    Active set in the manner of Lawson-Hanson/BVLS: variables at a bound whose gradient points
    outward are held; the rest jump to their subspace minimiser, or as far towards it as the
    bounds allow (the objective falls along that segment, convex), and the hit bound is held."""
    b = np.clip(start, lo, hi)
    eps = 1e-12 * (hi - lo)
    grad = g @ b - f
    held = ((b <= lo) & (grad >= 0)) | ((b >= hi) & (grad <= 0))
    b[held & (b <= lo)] = lo
    b[held & (b >= hi)] = hi
    for _ in range(iterations):
        free = ~held
        if free.any():
            target = np.linalg.solve(g[np.ix_(free, free)], f[free] - g[np.ix_(free, held)] @ b[held])
            cur = b[free]
            d = target - cur
            if np.any(target < lo - eps) or np.any(target > hi + eps):
                # Step towards the subspace minimiser until the first bound; hold what it hits.
                with np.errstate(divide="ignore", invalid="ignore"):
                    room = np.where(d < 0, (lo - cur) / d, np.where(d > 0, (hi - cur) / d, np.inf))
                alpha = float(np.clip(np.min(room), 0.0, 1.0))
                nb = cur + alpha * d
                hit = room <= alpha * (1 + 1e-12) + 1e-15
                nb[hit & (d < 0)] = lo
                nb[hit & (d > 0)] = hi
                b[free] = np.clip(nb, lo, hi)
                idx = np.flatnonzero(free)
                held[idx[hit]] = True
                continue
            b[free] = np.clip(target, lo, hi)
        # KKT: release the held variable whose gradient points most into the box, if any.
        grad = g @ b - f
        pull = np.where(held & (b <= lo), -grad, np.where(held & (b >= hi), grad, 0.0))
        k = int(np.argmax(pull))
        if pull[k] <= tol * max(1.0, float(np.abs(f).max())):
            break
        held[k] = False
    return b


@dataclass(frozen=True)
class MorphRig:
    """A head animated through its own morph targets.

    neutral: (n, 3) float32 head vertices; triangles: (m, 3) int32; names: (P,) the head's target
    names that are driven; targets: (P, n_moving, 3) float32 displacement per unit weight, on
    ``moving`` (n_moving,) int64 (the vertices any driven target moves); keymap: source
    coordinates -> weights; source: params (4,) -> source coordinates (k,) (e.g. ARKit-52
    weights of :func:`realtime_core.blendshapes.blendshape_weights`); meta: JSON-able description.
    """

    neutral: np.ndarray
    triangles: np.ndarray
    names: tuple[str, ...]
    targets: np.ndarray
    moving: np.ndarray
    keymap: KeyframeMap
    source: Callable[[np.ndarray], np.ndarray]
    meta: dict[str, Any] = field(default_factory=dict)
    # Set in __post_init__: the targets flattened to (P, n_moving*3) (a view of ``targets``).
    _rows: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        t = np.ascontiguousarray(self.targets, dtype=np.float32)
        if t.ndim != 3 or t.shape[0] != len(self.names) or t.shape[1:] != (len(self.moving), 3):
            raise ConfigError(
                f"morph targets {t.shape} do not match {len(self.names)} names, {len(self.moving)} moving vertices"
            )
        if self.keymap.n_keyframes != len(self.names):
            raise ConfigError(f"keyframe map has {self.keymap.n_keyframes} keyframes for {len(self.names)} targets")
        object.__setattr__(self, "targets", t)
        object.__setattr__(self, "neutral", np.asarray(self.neutral, dtype=np.float32))
        object.__setattr__(self, "triangles", np.asarray(self.triangles, dtype=np.int32))
        object.__setattr__(self, "moving", np.asarray(self.moving, dtype=np.int64))
        # (P, n_moving*3): one row-vector product per frame.
        object.__setattr__(self, "_rows", t.reshape(len(t), -1))

    def weights(self, params: np.ndarray) -> np.ndarray:
        """Mouth parameters (..., 4) (IOD) -> the head's target weights (..., P) float32."""
        p = np.asarray(params, dtype=np.float64)
        return self.keymap.weights(self.source(p)).astype(np.float32)

    def displacements(self, params: np.ndarray) -> np.ndarray:
        """Head displacement (n_moving, 3) float32 for params (4,)."""
        w = self.weights(np.asarray(params, dtype=np.float64).reshape(4))
        # w @ (P, n_moving*3): a row-major product streams each target once; the (n_moving*3, P)
        # matrix times w walks P-float rows and took ~2.3x longer per frame (a server's vertex viewer).
        return np.dot(w, self._rows).reshape(-1, 3)

    def deformed(self, params: np.ndarray) -> np.ndarray:
        """All head vertices (n, 3) float32 for params (4,)."""
        out = np.array(self.neutral, dtype=np.float32, copy=True)
        out[self.moving] += self.displacements(params)
        return out

    def dense_targets(self) -> np.ndarray:
        """(P, n, 3) float32 targets over all vertices (for exports)."""
        out = np.zeros((len(self.names), len(self.neutral), 3), dtype=np.float32)
        out[:, self.moving] = self.targets
        return out
