"""MU parameters <-> keyframe (blendshape) weights by least squares (paper 002 eq. 3-4).

A keyframe set is ``K = [kappa'_1 .. kappa'_P]``: the deformation ``(D,)`` of each keyframe
relative to the neutral face, in the same landmark space as the Motion Units. A face shape is
``s_0 + K b`` (keyframe weights ``b (P,)``) or ``s_0 + d`` with ``d`` from eq. 2, so

    b = (K^T K + lambda I)^-1 K^T d              (eq. 4, third line; lambda = 0 is the paper's)
    c_0 = M_0^T (K b - m_00)                     (eq. 4, first line)
    c_k = M_k^T (K b - m_00 - M_0 c_0 - alpha m_k0) / alpha    (eq. 4, second line)

We write the keyframes as deformations (``kappa' - s_0``) so ``s_0`` cancels.

**Keyframes as the MUs see them** (:func:`in_mu_space`). The paper's ``kappa'_i`` are training
samples of the MUs, i.e. vectors the MUs represent. A keyframe given from elsewhere (a head's morph
target carried onto the landmarks, a median of noisy measured frames) also has a part no MU can
represent; eq. 4's least squares in landmark space then trades MU error for fitting that part, and
the round trip MUPs -> keyframes -> MUPs loses what the keyframes' span misses. Projecting each
keyframe onto the MU subspace first (``M_0^T M_0 kappa'``) makes eq. 4 solve the MUPs themselves:
the unconstrained round trip is exact whenever the projected keyframes span the ``A_0`` MUs.

``lambda`` (relative to
the mean squared column norm of K) keeps the solve stable when keyframes are nearly collinear (the
52 ARKit targets are, in a few dozen landmarks); ``nonnegative=True`` solves the same problem with
``b >= 0`` (scipy's NNLS), which is what engines expect of blendshape weights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError, InvalidFeaturesError
from realtime_core.motion_units.units import ExpressionUnits, MotionUnits, analyse, compose


@dataclass(frozen=True, kw_only=True, eq=False)
class KeyframeSet:
    """names: ``P`` keyframe names; shapes: ``(D, P)`` float64 deformation of each keyframe (columns);
    ridge: lambda of eq. 4 relative to the mean squared column norm (0 = plain least squares)."""

    names: tuple[str, ...]
    shapes: np.ndarray
    ridge: float = 0.0

    def __post_init__(self) -> None:
        k = np.asarray(self.shapes, dtype=np.float64)
        if k.ndim != 2 or k.shape[1] != len(self.names) or k.shape[1] == 0:
            raise ConfigError(f"keyframe shapes must be (D, {len(self.names)}), got {k.shape}")
        if len(set(self.names)) != len(self.names):
            raise ConfigError("keyframe names must be unique")
        if not np.isfinite(k).all():
            raise ConfigError("keyframe shapes contain NaN or inf")
        if not self.ridge >= 0:
            raise ConfigError(f"ridge must be >= 0, got {self.ridge}")
        k.setflags(write=False)
        object.__setattr__(self, "shapes", k)
        lam = self.ridge * float((k**2).sum(axis=0).mean())
        gram = k.T @ k + lam * np.eye(k.shape[1])
        if lam == 0 and np.linalg.matrix_rank(gram) < k.shape[1]:
            raise ConfigError("keyframes are linearly dependent: plain least squares is undefined (set ridge > 0)")
        solve = np.linalg.solve(gram, k.T)  # (P, D): b = solve @ d
        solve.setflags(write=False)
        object.__setattr__(self, "_solve", solve)
        object.__setattr__(self, "_lam", lam)

    @property
    def solver(self) -> np.ndarray:
        """``(P, D)``: ``(K^T K + lambda I)^-1 K^T``."""
        return self._solve  # type: ignore[attr-defined]

    def ridge_rows(self) -> np.ndarray:
        """``(D + P, P)``: ``[K; sqrt(lambda) I]``, the ridge as extra rows, so ``min |K b - d|^2 + lambda |b|^2``
        is the least squares of ``[d; 0]`` (what :meth:`weights` gives NNLS with ``b >= 0``; a caller adding
        rows of its own stacks them under these)."""
        p = self.shapes.shape[1]
        return np.vstack([self.shapes, np.sqrt(self._lam) * np.eye(p)])  # type: ignore[attr-defined]

    def weights(self, d: np.ndarray, *, nonnegative: bool = False) -> np.ndarray:
        """Deformations ``(..., D)`` -> keyframe weights ``(..., P)``."""
        x = np.asarray(d, dtype=np.float64)
        if x.shape[-1] != self.shapes.shape[0]:
            raise InvalidFeaturesError(f"deformations must be (..., {self.shapes.shape[0]}), got {x.shape}")
        if not nonnegative:
            return x @ self.solver.T
        # Imported here: scipy.optimize costs 0.3-0.7 s to import, and every unit-corpus load (each `facecast say`)
        # imports this package for MotionUnits without ever solving a nonnegative fit.
        from scipy.optimize import nnls

        p = self.shapes.shape[1]
        a = self.ridge_rows()
        flat = x.reshape(-1, x.shape[-1])
        out = np.array([nnls(a, np.concatenate([row, np.zeros(p)]))[0] for row in flat])
        return out.reshape((*x.shape[:-1], p))

    def deformation(self, b: np.ndarray) -> np.ndarray:
        """Keyframe weights ``(..., P)`` -> deformation ``(..., D)`` (eq. 3's ``K b``)."""
        b = np.asarray(b, dtype=np.float64)
        if b.shape[-1] != len(self.names):
            raise InvalidFeaturesError(f"keyframe weights must be (..., {len(self.names)}), got {b.shape}")
        return b @ self.shapes.T


def mups_to_keyframes(
    keys: KeyframeSet,
    utterance: MotionUnits,
    umup: np.ndarray,
    expression: ExpressionUnits | None = None,
    emup: np.ndarray | None = None,
    alpha: float = 1.0,
    *,
    nonnegative: bool = False,
) -> np.ndarray:
    """Eq. 4 (third line): MUPs -> keyframe weights ``(..., P)``."""
    return keys.weights(compose(utterance, umup, expression, emup, alpha), nonnegative=nonnegative)


def keyframes_to_mups(
    keys: KeyframeSet,
    utterance: MotionUnits,
    b: np.ndarray,
    expression: ExpressionUnits | None = None,
    alpha: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4 (first two lines): keyframe weights ``(..., P)`` -> (UMUPs, EMUPs)."""
    return analyse(utterance, expression, keys.deformation(b), alpha)


def in_mu_space(keys: KeyframeSet, utterance: MotionUnits, *, ridge: float | None = None) -> KeyframeSet:
    """The keyframes projected onto the Utterance MUs' subspace (``M_0^T M_0 K``; see the module doc),
    same names. ``ridge`` defaults to the set's own, and to at least 1e-6 when there are more keyframes
    than MUs (their projections are then linearly dependent; the solve tends to the minimum-norm one)."""
    u = utterance.units
    if ridge is None:
        ridge = max(keys.ridge, 1e-6) if len(keys.names) > utterance.n_units else keys.ridge
    return KeyframeSet(names=keys.names, shapes=u.T @ (u @ keys.shapes), ridge=ridge)


def round_trip_error(
    keys: KeyframeSet, utterance: MotionUnits, umup: np.ndarray, *, nonnegative: bool = False
) -> np.ndarray:
    """``(A,)``: RMS error per MU of MUPs -> keyframes -> MUPs over the frames ``umup (T, A)``, divided
    by each MU's range (max - min) over those frames. ``nonnegative``: weights solved with ``b >= 0``."""
    c = np.asarray(umup, dtype=np.float64)
    b = mups_to_keyframes(keys, utterance, c, nonnegative=nonnegative)
    back, _ = keyframes_to_mups(keys, utterance, b)
    rng = c.max(axis=0) - c.min(axis=0)
    return np.sqrt(((back - c) ** 2).mean(axis=0)) / np.where(rng > 0, rng, 1.0)
