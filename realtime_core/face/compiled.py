"""Numba-compiled bounded keyframe solve (``KeyframeMap.weights(..., kernel="numba")``).

Why compiled: a head driven through its own morph targets solves a 52-variable box-constrained QP
per frame (:func:`realtime_core.face.keyframes._box_qp`, an active-set method). In numpy that is
a few hundred small calls, ~0.35 ms per frame: on a server the biggest cost of a vertex viewer's
session. This is the same active-set iteration, step for step, in one compiled call; the numpy
function stays the reference and tests/realtime_core/face/test_keyframes.py holds them equal.

Compiled lazily on first use and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def box_qp(  # pragma: no cover - compiled
    g: np.ndarray, f: np.ndarray, lo: float, hi: float, start: np.ndarray, iterations: int, tol: float
) -> np.ndarray:
    """min 1/2 b^T g b - f^T b subject to lo <= b <= hi: ``_box_qp`` of keyframes.py, compiled."""
    n = f.shape[0]
    b = np.minimum(np.maximum(start, lo), hi)
    eps = 1e-12 * (hi - lo)
    grad = np.dot(g, b) - f
    held = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        held[i] = (b[i] <= lo and grad[i] >= 0) or (b[i] >= hi and grad[i] <= 0)
        if held[i] and b[i] <= lo:
            b[i] = lo
        if held[i] and b[i] >= hi:
            b[i] = hi
    fmax = 0.0
    for i in range(n):
        fmax = max(fmax, abs(f[i]))
    limit = tol * max(1.0, fmax)
    for _ in range(iterations):
        free = np.flatnonzero(~held)
        fixed = np.flatnonzero(held)
        nf = free.size
        if nf > 0:
            gff = np.empty((nf, nf))
            rhs = np.empty(nf)
            for a in range(nf):
                s = f[free[a]]
                for c in range(fixed.size):
                    s -= g[free[a], fixed[c]] * b[fixed[c]]
                rhs[a] = s
                for c in range(nf):
                    gff[a, c] = g[free[a], free[c]]
            target = np.linalg.solve(gff, rhs)
            outside = False
            for a in range(nf):
                if target[a] < lo - eps or target[a] > hi + eps:
                    outside = True
            if outside:
                # Step towards the subspace minimiser until the first bound; hold what it hits.
                room = np.empty(nf)
                for a in range(nf):
                    d = target[a] - b[free[a]]
                    if d < 0:
                        room[a] = (lo - b[free[a]]) / d
                    elif d > 0:
                        room[a] = (hi - b[free[a]]) / d
                    else:
                        room[a] = np.inf
                alpha = min(max(room.min(), 0.0), 1.0)
                nb = np.empty(nf)
                for a in range(nf):
                    cur = b[free[a]]
                    d = target[a] - cur
                    nb[a] = cur + alpha * d
                    if room[a] <= alpha * (1 + 1e-12) + 1e-15:
                        if d < 0:
                            nb[a] = lo
                        elif d > 0:
                            nb[a] = hi
                        held[free[a]] = True
                for a in range(nf):
                    b[free[a]] = min(max(nb[a], lo), hi)
                continue
            for a in range(nf):
                b[free[a]] = min(max(target[a], lo), hi)
        # KKT: release the held variable whose gradient points most into the box, if any.
        grad = np.dot(g, b) - f
        k = 0
        best = -np.inf
        for i in range(n):
            p = 0.0
            if held[i] and b[i] <= lo:
                p = -grad[i]
            elif held[i] and b[i] >= hi:
                p = grad[i]
            if p > best:
                best = p
                k = i
        if best <= limit:
            break
        held[k] = False
    return b


@njit(cache=True, nogil=True)
def keyframe_weights(  # pragma: no cover - compiled
    x: np.ndarray,
    cross: np.ndarray,
    chol: np.ndarray,
    gram: np.ndarray,
    lo: float,
    hi: float,
    iterations: int,
    tol: float,
) -> np.ndarray:
    """One frame of ``KeyframeMap.weights`` in one call: source coordinates ``x (k,)`` -> weights (P,).

    The right-hand side ``cross @ x``, the unbounded start by the Cholesky factor (``chol`` (P, P):
    scipy's ``cho_factor`` upper factor U, gram = U^T U; only its upper triangle is read) and
    :func:`box_qp`. Per frame the three separate calls (a GEMV, scipy's ``cho_solve`` with its
    argument checks, the solve) cost ~25 us, mostly call overhead; this is ~8 us."""
    p = cross.shape[0]
    f = np.dot(cross, x)
    y = np.empty(p)  # U^T y = f
    for i in range(p):
        acc = f[i]
        for k in range(i):
            acc -= chol[k, i] * y[k]
        y[i] = acc / chol[i, i]
    start = np.empty(p)  # U start = y
    for i in range(p - 1, -1, -1):
        acc = y[i]
        for k in range(i + 1, p):
            acc -= chol[i, k] * start[k]
        start[i] = acc / chol[i, i]
    return box_qp(gram, f, lo, hi, start, iterations, tol)
