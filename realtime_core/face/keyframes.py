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

Lip contact: the fit may cross the lips where the motion it reproduces does not (an OVR head's PP
viseme, pressed and rolled lips, chosen for a closed smile, drove the lips 0.017 IOD through each
other). Given the reference face's lip gaps (IOD, at m columns along the contact line) as linear
functions of the weights, ``rest + R b``, and of the source, ``rest + S x``, the solve keeps

    rest + R b >= min(0, rest + S x)        (never crosses more than the motion itself)

by its Lagrange dual: b(lambda) solves the box QP with right-hand side C x + R^T lambda, and each
gap grows with its own multiplier, so a few 1-D searches per violated column find lambda >= 0.
Frames whose unconstrained fit keeps the lips apart (all but closed-lip frames on such heads, every
frame of a head whose targets are the reference's own) cost one comparison more.

Closed lips held closed (branch i12ovr): the same fit may also *open* lips the motion keeps closed (an
OVR head at /m/ took viseme_U and viseme_E and parted them 0.03 IOD). Each column also has a ceiling,
``gap <= max(0, s) + LIP_OPEN_TOL + LIP_OPEN_RAMP max(0, s - LIP_CLOSED_GAP)`` with s = rest + S x, in
the same dual with the column's multiplier negative (closing); the floor wins where both cannot hold.

:class:`MorphRig` applies b to the head's own targets; it has the interface the renderer, the
exporters and the server's sessions use for a :class:`realtime_core.face.Rig` (``neutral``,
``triangles``, ``moving``, ``displacements(params)``, ``deformed(params)``, ``meta``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from realtime_core.errors import ConfigError

if TYPE_CHECKING:
    from realtime_core.face.checks import PoseBound

CONTACT_TOL = 1e-5
"""IOD: a lip gap below its floor by less than this is kept (the dual search stops within it)."""
LIP_OPEN_TOL = 0.003
"""IOD: how far past the source's own gap the fit may open a closed lip column. The rig checks' lip gap
at /m/ is advisory above 0.01 and the built-in head's source gap there is 0.006; an OVR-visemes head
rounds closed lips only with viseme_U, which opens them, and at 0.002 its rounding probe
(``assets.heads.targets.ENOUGH_PROBES``, limit 0.9) reached residual 0.91 (0.003: 0.88)."""
LIP_CLOSED_GAP = 0.02
"""IOD: a lip column whose source gap is below this is closed or nearly (the built-in head's inner lips
rest 0.007 apart, its other reference columns 0.027-0.113: the ceiling holds the lips' contact, not
columns the lips' shape keeps apart, which the visemes cannot all close at once)."""
LIP_OPEN_RAMP = 10.0
"""Per IOD of source gap above LIP_CLOSED_GAP, how much the ceiling rises: it lets go within ~0.01 IOD
(0.1 IOD of slack) and without a step from one frame to the next."""
CONTACT_SWEEPS = 4
"""Dual coordinate-ascent steps per contact column (one or two columns bind on a closed-lip frame)."""
CONTACT_SEARCH = 40
"""Box-QP solves per 1-D multiplier search (doubling, then bisection)."""


@dataclass(frozen=True)
class KeyframeMap:
    """Source coordinates x (k,) -> keyframe weights b (P,) (paper 002 eq. 4 with bounds).

    gram: (P, P) K'^T K' (+ ridge); cross: (P, k) K'^T A; lo, hi: weight bounds.
    Build it with :meth:`from_reference`."""

    gram: np.ndarray
    cross: np.ndarray
    lo: float = 0.0
    hi: float = 1.0
    # Lip contact (see the module docstring), all or none: contact_rest (m,) the reference's lip gaps
    # (IOD) at rest, contact_rows (m, P) per unit keyframe weight, contact_source (m, k) per unit source.
    contact_rest: np.ndarray | None = None
    contact_rows: np.ndarray | None = None
    contact_source: np.ndarray | None = None
    # Set in __post_init__: the Cholesky factor of the Gram matrix; [cross | contact_rows^T] (P, k + m).
    _chol: tuple[np.ndarray, bool] = field(init=False, repr=False, compare=False)
    _cross_contact: np.ndarray = field(init=False, repr=False, compare=False)
    _contact_slope: np.ndarray = field(init=False, repr=False, compare=False)
    _check: np.ndarray = field(init=False, repr=False, compare=False)
    _check_limit: np.ndarray = field(init=False, repr=False, compare=False)

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
        given = [a is not None for a in (self.contact_rest, self.contact_rows, self.contact_source)]
        if any(given) and not all(given):
            raise ConfigError("lip contact needs contact_rest, contact_rows and contact_source together")
        cc = c
        if all(given):
            rest = np.asarray(self.contact_rest, dtype=np.float64).reshape(-1)
            rows = np.asarray(self.contact_rows, dtype=np.float64)
            src = np.asarray(self.contact_source, dtype=np.float64)
            if rows.shape != (len(rest), g.shape[0]) or src.shape != (len(rest), c.shape[1]):
                raise ConfigError(
                    f"lip contact rows {rows.shape} / source {src.shape} must be ({len(rest)}, {g.shape[0]}) / "
                    f"({len(rest)}, {c.shape[1]})"
                )
            object.__setattr__(self, "contact_rest", rest)
            object.__setattr__(self, "contact_rows", rows)
            object.__setattr__(self, "contact_source", src)
            cc = np.ascontiguousarray(np.hstack([c, rows.T]))
            # Each column's gap per unit of its own multiplier with no bound held (R H^-1 R^T diagonal).
            slope = np.maximum(np.einsum("mp,pm->m", rows, cho_solve(self._chol, rows.T)), 1e-12)
            object.__setattr__(self, "_contact_slope", slope)
            # [b; x] -> three rows per column against _check_limit: the floor (-R b <= rest + CONTACT_TOL:
            # the gap at or above 0) and the ceiling's two linear lower bounds (R b - S x <= LIP_OPEN_TOL;
            # R b - (1 + ramp) S x <= LIP_OPEN_TOL + ramp (rest - LIP_CLOSED_GAP)); gaps: rest + R b, rest + S x.
            ramp = LIP_OPEN_RAMP
            check = np.block([[-rows, np.zeros_like(src)], [rows, -src], [rows, -(1.0 + ramp) * src]])
            limit = np.concatenate(
                [rest + CONTACT_TOL, np.full(len(rest), LIP_OPEN_TOL), LIP_OPEN_TOL + ramp * (rest - LIP_CLOSED_GAP)]
            )
            object.__setattr__(self, "_check", np.ascontiguousarray(check))
            object.__setattr__(self, "_check_limit", limit)
        object.__setattr__(self, "_cross_contact", cc)

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
        contact: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> KeyframeMap:
        """keyframes: (P, d) the correspondents kappa'_i as flat reference displacements; source:
        (k, d) the reference displacement per unit of each source coordinate (the columns of A).
        ridge: relative to the mean diagonal of K'^T K' (keeps the normal equations definite).
        contact: None, or (rest (m,), gap (m, d)) the reference's lip gaps (IOD) at rest and per unit
        reference displacement (a row of +-up / iod at the two lips' vertices): kept apart."""
        kf = np.asarray(keyframes, dtype=np.float64)
        a = np.asarray(source, dtype=np.float64)
        if kf.ndim != 2 or a.ndim != 2 or kf.shape[1] != a.shape[1]:
            raise ConfigError(f"keyframes (P, d) and source (k, d) must share d, got {kf.shape} and {a.shape}")
        g = kf @ kf.T
        scale = float(np.mean(np.diag(g))) if g.size else 1.0
        if not scale > 0:
            raise ConfigError("every keyframe correspondent is zero: nothing to solve for")
        g = g + ridge * scale * np.eye(len(g))
        if contact is None:
            return cls(gram=g, cross=kf @ a.T, lo=lo, hi=hi)
        rest, gap = (np.asarray(z, dtype=np.float64) for z in contact)
        if gap.ndim != 2 or gap.shape != (len(rest), kf.shape[1]):
            raise ConfigError(f"lip contact gap rows must be ({len(rest)}, {kf.shape[1]}), got {gap.shape}")
        return cls(
            gram=g,
            cross=kf @ a.T,
            lo=lo,
            hi=hi,
            contact_rest=rest,
            contact_rows=gap @ kf.T,
            contact_source=gap @ a.T,
        )

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
                xc = np.ascontiguousarray(x)
                b = keyframe_weights(xc, self.cross, chol, g, self.lo, self.hi, iterations, tol)
                return b if self._apart_already(xc, b, kernel) else self._apart(xc, b, kernel, iterations, tol)
            rows = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
            out = np.empty((len(rows), self.n_keyframes))
            for i, row in enumerate(rows):
                b = keyframe_weights(row, self.cross, chol, g, self.lo, self.hi, iterations, tol)
                out[i] = b if self._apart_already(row, b, kernel) else self._apart(row, b, kernel, iterations, tol)
            return out.reshape((*x.shape[:-1], self.n_keyframes))
        rows = np.ascontiguousarray(x.reshape(-1, x.shape[-1]))
        out = np.empty((len(rows), self.n_keyframes))
        for i, row in enumerate(rows):
            b = self._solve(row, None, "numpy", iterations, tol)
            out[i] = b if self._apart_already(row, b) else self._apart(row, b, "numpy", iterations, tol)
        return out.reshape((*x.shape[:-1], self.n_keyframes))

    def _solve(self, x: np.ndarray, lam: np.ndarray | None, kernel: str, iterations: int, tol: float) -> np.ndarray:
        """The box QP for one frame x (k,) with the lip multipliers lam (m,) (None: none)."""
        if kernel == "numba":
            from realtime_core.face.compiled import keyframe_weights

            xl, cross = (x, self.cross) if lam is None else (np.concatenate([x, lam]), self._cross_contact)
            return keyframe_weights(xl, cross, self._chol[0], self.gram, self.lo, self.hi, iterations, tol)
        f = self.cross @ x
        if lam is not None:
            f = f + self._cross_contact[:, len(x) :] @ lam
        return _box_qp(self.gram, f, self.lo, self.hi, cho_solve(self._chol, f), iterations, tol)

    def _apart_already(self, x: np.ndarray, b: np.ndarray, kernel: str = "numpy") -> bool:
        """No lip contact, or every column's gap at or above 0 (so above any floor) and under one of two
        linear lower bounds on its ceiling (:meth:`_bounds`: source gap + LIP_OPEN_TOL, and that plus
        LIP_OPEN_RAMP (source gap - LIP_CLOSED_GAP)): the common frame, one small product
        (:attr:`_check`). A frame this does not clear may still be within its bounds (:meth:`_dual`
        then returns b unchanged, bit for bit)."""
        if self.contact_rows is None:
            return True
        if kernel == "numba":
            from realtime_core.face.compiled import lip_bounds_clear

            return bool(lip_bounds_clear(self._check, self._check_limit, b, x))
        r = (self._check @ np.concatenate((b, x)) - self._check_limit).reshape(3, -1)
        return bool(np.maximum(r[0], np.minimum(r[1], r[2])).max() <= 0.0)

    def _bounds(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The lip columns' floor and ceiling (m,) (IOD) for one frame x (k,): never crossed more than
        the source crosses them, never opened more than LIP_OPEN_TOL past the source's own gap plus
        LIP_OPEN_RAMP times how far the source gap is above LIP_CLOSED_GAP (the ceiling binds on closed and
        nearly closed lips and rises steeply but continuously away from them: no frame jumps as it lets go)."""
        assert self.contact_rest is not None and self.contact_source is not None
        src = self.contact_rest + self.contact_source @ x
        # A source that crosses the lips (the closure check's mouth_open < 0) closes the ceiling no lower
        # than touching: the fit is never pushed through.
        ceil = np.maximum(0.0, src) + LIP_OPEN_TOL + LIP_OPEN_RAMP * np.maximum(0.0, src - LIP_CLOSED_GAP)
        return np.minimum(0.0, src), ceil

    def _apart(self, x: np.ndarray, b: np.ndarray, kernel: str, iterations: int, tol: float) -> np.ndarray:
        """The weights for one frame x (k,) (b: its unconstrained solution) with each lip column between
        its floor and ceiling (module docstring): dual coordinate ascent on the most violated bound, each
        step a bracketed 1-D search on its column's multiplier (signed: positive opens, negative closes;
        the gap is nondecreasing and piecewise linear in it: secant steps, bisection when a secant step
        leaves the bracket's same end twice), ending on the feasible side."""
        assert self.contact_rest is not None and self.contact_rows is not None and self.contact_source is not None
        floor, ceil = self._bounds(x)
        out = self._dual(x, b, floor, ceil, kernel, iterations, tol)
        if (self.contact_rest + self.contact_rows @ out - floor).min() < -CONTACT_TOL:
            # Ceilings and floors the box cannot meet together (an OVR head's lowered upper lip: closing
            # one column crossed another): the floor wins, as it did before there were ceilings.
            out = self._dual(x, b, floor, np.full_like(ceil, np.inf), kernel, iterations, tol)
        return out

    def _dual(
        self,
        x: np.ndarray,
        b: np.ndarray,
        floor: np.ndarray,
        ceil: np.ndarray,
        kernel: str,
        iterations: int,
        tol: float,
    ) -> np.ndarray:
        """:meth:`_apart`'s dual coordinate ascent for given floor and ceiling (m,) (a ceiling the box
        cannot meet is dropped)."""
        assert self.contact_rest is not None and self.contact_rows is not None
        rest, rows = self.contact_rest, self.contact_rows
        ceil = ceil.copy()
        lam = np.zeros(len(rest))
        aim = 0.5 * CONTACT_TOL
        for _ in range(CONTACT_SWEEPS * len(rest)):
            gap = rest + rows @ b
            under, over = gap - floor, ceil - gap  # each >= 0 where its bound holds
            j_lo, j_hi = int(np.argmin(under)), int(np.argmin(over))
            if min(under[j_lo], over[j_hi]) >= -CONTACT_TOL:
                break
            # s = +1: raise column j to its floor (multiplier up); s = -1: lower it to its ceiling (down).
            j, s, bound = (j_lo, 1.0, floor[j_lo]) if under[j_lo] <= over[j_hi] else (j_hi, -1.0, ceil[j_hi])
            # u = s * lam[j]; slack(u) = s * (gap_j - bound) is nondecreasing in u, feasible at >= 0.
            lo_u, g_lo = s * float(lam[j]), s * float(gap[j] - bound)
            if lo_u < 0:
                # The multiplier holds column j's other bound: coordinate ascent goes through 0 first (at 0
                # this bound may already hold; the other, if violated there, is the next step's).
                zero = lam.copy()
                zero[j] = 0.0
                b0 = self._solve(x, zero if zero.any() else None, kernel, iterations, tol)
                g0 = s * float(rest[j] + rows[j] @ b0 - bound)
                if g0 >= 0.0:
                    lam, b = zero, b0
                    continue
                lo_u, g_lo = 0.0, g0
            hi_u, g_hi, b_hi, bracketed = 0.0, 0.0, b, False
            step = (aim - g_lo) / self._contact_slope[j]  # the unbounded slope: a lower bound on the step
            last, same = "", 0  # the bracket end moved last, and how many times in a row
            for _ in range(CONTACT_SEARCH):
                if not bracketed:
                    t = lo_u + step
                elif same >= 2:
                    t = 0.5 * (lo_u + hi_u)
                else:
                    t = lo_u + (hi_u - lo_u) * (aim - g_lo) / (g_hi - g_lo)
                trial = lam.copy()
                trial[j] = s * t
                bt = self._solve(x, trial, kernel, iterations, tol)
                gj = s * float(rest[j] + rows[j] @ bt - bound)
                side = "hi" if gj >= 0.0 else "lo"
                same, last = (same + 1 if side == last else 1), side
                if gj >= 0.0:
                    hi_u, g_hi, b_hi, bracketed = t, gj, bt, True
                    if gj <= CONTACT_TOL:
                        break
                else:
                    lo_u, g_lo = t, gj
                    if not bracketed:
                        step *= 2.0
            if not bracketed:
                if s < 0:
                    # The box cannot close this column that far: let it be (and let go of what it held).
                    ceil[j] = np.inf
                    if lam[j] < 0:
                        lam[j] = 0.0
                        b = self._solve(x, lam if lam.any() else None, kernel, iterations, tol)
                    continue
                break  # the weights' bounds cannot open this column further: the best the box allows
            lam[j], b = s * hi_u, b_hi
        return b

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
    bound: PoseBound | None = None
    """The parameters the rig accepts (:func:`realtime_core.face.checks.checked_bound`, set on every
    :class:`assets.heads.head.Head`): params outside it give the weights of its nearest point. None: any."""
    rest: np.ndarray | None = None
    """(P,) float32 weights added to every frame's (None: none), so that params 0 are lips touching on a head
    modelled with its lips apart (the mouth parameters' closed pose; the fit's weights alone leave such lips as far
    apart as modelled at every /m b p/): its jaw target below 0 (:func:`assets.heads.head.closing_rest`). The head as
    modelled stays the rig's ``neutral``; weights may then be below 0."""
    face_recipe: np.ndarray | None = None
    """(E, F) float32: the last F of :attr:`names` are the head's own face shapes (cheeks, eyes, brows) that no mouth
    parameter drives, weighted per expression of :data:`realtime_core.expressions.EXPRESSIONS` at full intensity
    (:func:`realtime_core.expressions.face_shapes`); :meth:`weights` gives them ``expression @ face_recipe`` (0 with no
    expression). Why: through the four parameters alone an expression moves only the mouth, and on a head with brow
    and eye targets a "surprise" without raised brows or wide eyes looked like no expression. None: no such shapes."""
    # Set in __post_init__: the targets flattened to (P, n_moving*3) (a view of ``targets``).
    _rows: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        t = np.ascontiguousarray(self.targets, dtype=np.float32)
        if t.ndim != 3 or t.shape[0] != len(self.names) or t.shape[1:] != (len(self.moving), 3):
            raise ConfigError(
                f"morph targets {t.shape} do not match {len(self.names)} names, {len(self.moving)} moving vertices"
            )
        n_face = 0
        if self.face_recipe is not None:
            recipe = np.asarray(self.face_recipe, dtype=np.float32)
            if recipe.ndim != 2 or not 0 < recipe.shape[1] < len(self.names) or not np.isfinite(recipe).all():
                raise ConfigError(f"face recipe {recipe.shape} must be (E, F) finite, F < {len(self.names)} targets")
            object.__setattr__(self, "face_recipe", recipe)
            n_face = recipe.shape[1]
        if self.keymap.n_keyframes != len(self.names) - n_face:
            raise ConfigError(
                f"keyframe map has {self.keymap.n_keyframes} keyframes for {len(self.names) - n_face} speech targets"
            )
        object.__setattr__(self, "targets", t)
        object.__setattr__(self, "neutral", np.asarray(self.neutral, dtype=np.float32))
        object.__setattr__(self, "triangles", np.asarray(self.triangles, dtype=np.int32))
        object.__setattr__(self, "moving", np.asarray(self.moving, dtype=np.int64))
        if self.rest is not None:
            rest = np.asarray(self.rest, dtype=np.float32).reshape(-1)
            if rest.shape != (len(self.names),) or not np.isfinite(rest).all():
                raise ConfigError(f"rest weights {np.shape(self.rest)} must be {len(self.names)} finite numbers")
            object.__setattr__(self, "rest", rest)
        # (P, n_moving*3): one row-vector product per frame.
        object.__setattr__(self, "_rows", t.reshape(len(t), -1))

    @property
    def n_face(self) -> int:
        """How many of :attr:`names` (the last ones) are face shapes driven by expressions only."""
        return 0 if self.face_recipe is None else int(self.face_recipe.shape[1])

    def weights(self, params: np.ndarray, expression: np.ndarray | None = None) -> np.ndarray:
        """Mouth parameters (..., 4) (IOD) -> the head's target weights (..., P) float32 (the parameters within
        :attr:`bound`, plus :attr:`rest`: every consumer, renderer, server deltas and morph weights, exports, goes
        through here). ``expression`` (..., E) intensities in [0, 1] (None: none) drive the face shapes
        (:attr:`face_recipe`); the mouth takes the expression through ``params`` already (paper 002 eq. 2)."""
        p = np.asarray(params, dtype=np.float64)
        if self.bound is not None:
            p = self.bound(p)
        w = self.keymap.weights(self.source(p)).astype(np.float32)
        if self.face_recipe is not None:
            face = np.zeros((*w.shape[:-1], self.n_face), dtype=np.float32)
            if expression is not None:
                a = np.asarray(expression, dtype=np.float32)
                face = np.clip(np.broadcast_to(a @ self.face_recipe, face.shape), 0.0, 1.0).astype(np.float32)
            w = np.concatenate([w, face], axis=-1)
        return w if self.rest is None else w + self.rest

    def displacements(self, params: np.ndarray, expression: np.ndarray | None = None) -> np.ndarray:
        """Head displacement (n_moving, 3) float32 for params (4,) (and expression intensities (E,), None: none)."""
        w, rows = self.active(self.weights(np.asarray(params, dtype=np.float64).reshape(4), expression))
        # w @ (P, n_moving*3): a row-major product streams each target once; the (n_moving*3, P)
        # matrix times w walks P-float rows and took ~2.3x longer per frame (a server's vertex viewer).
        return np.dot(w, rows).reshape(-1, 3)

    def active(self, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Target weights (..., P) -> (the weights, the flat targets (P', n_moving*3)) a product needs: without the
        face shapes when every one of them is 0 (no expression), so a frame without one costs what it did before the
        rig had them (the built-in head: 22 of 35 targets). Exact: the dropped terms are zeros added last."""
        if self.n_face and not np.any(weights[..., -self.n_face :]):
            return weights[..., : -self.n_face], self._rows[: len(self.names) - self.n_face]
        return weights, self._rows

    @property
    def flat_targets(self) -> np.ndarray:
        """The targets as (P, n_moving*3) float32, C-contiguous (a view of ``targets``; do not write)."""
        return self._rows

    def displacements_rows(self, weights: np.ndarray, *, kernel: str = "numba") -> np.ndarray:
        """Target weights (B, P) (each row a frame's :meth:`weights`) -> flat displacements
        (B, n_moving*3) float32, head units, vertex-major as ``displacements(...).reshape(-1)``.

        kernel "numba": one pass over the targets for all B frames
        (:func:`realtime_core.face.compiled.morph_displacements`, a fixed summation order: a frame's
        row is the same bits at any B); "numpy": the reference, each row numpy's product as
        :meth:`displacements` computes it (equal to the compiled rows to float32 rounding)."""
        w = np.ascontiguousarray(weights, dtype=np.float32)
        if w.ndim != 2 or w.shape[1] != len(self.names):
            raise ConfigError(f"weights must be (B, {len(self.names)}), got {w.shape}")
        w, rows = self.active(w)
        if kernel == "numpy":
            return np.stack([np.dot(row, rows) for row in w]) if len(w) else np.empty((0, rows.shape[1]))
        if kernel != "numba":
            raise ConfigError(f"kernel must be 'numba' or 'numpy', got {kernel!r}")
        from realtime_core.face.compiled import morph_displacements  # numba's import is paid only here

        return morph_displacements(np.ascontiguousarray(w), rows, np.empty((len(w), rows.shape[1]), dtype=np.float32))

    def deformed(self, params: np.ndarray, expression: np.ndarray | None = None) -> np.ndarray:
        """All head vertices (n, 3) float32 for params (4,) (and expression intensities (E,), None: none)."""
        out = np.array(self.neutral, dtype=np.float32, copy=True)
        out[self.moving] += self.displacements(params, expression)
        return out

    def dense_targets(self) -> np.ndarray:
        """(P, n, 3) float32 targets over all vertices (for exports)."""
        out = np.zeros((len(self.names), len(self.neutral), 3), dtype=np.float32)
        out[:, self.moving] = self.targets
        return out
