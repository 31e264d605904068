"""Numba-compiled bounded keyframe solve (``KeyframeMap.weights(..., kernel="numba")``).

Why compiled: a head driven through its own morph targets solves a 52-variable box-constrained QP
per frame (:func:`realtime_core.face.keyframes._box_qp`, an active-set method). In numpy that is
a few hundred small calls, ~0.35 ms per frame: on a server the biggest cost of a vertex viewer's
session. This is the same active-set iteration, step for step, in one compiled call; the numpy
function stays the reference and tests/realtime_core/face/test_keyframes.py holds them equal.

Compiled lazily on first use and cached next to this file (``cache=True``). Written as plain loops
over preallocated arrays, with no numpy array expressions, ``np.dot`` or ``np.linalg``: numba compiles
each of those into a large block of code. With them (``np.linalg.solve`` the largest) a process whose
first numba call this was spent 9.6 s of CPU (24 s wall at load 6.7; it was most of the first
``facecast say`` of a fresh clone); as loops 3.2-3.7 s, of which ~1.3 s is numba's own start
(compiling a trivial kernel), at no cost per frame (8 us min over the built-in head's map either way).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def box_qp(  # pragma: no cover - compiled
    g: np.ndarray, f: np.ndarray, lo: float, hi: float, start: np.ndarray, iterations: int, tol: float
) -> np.ndarray:
    """min 1/2 b^T g b - f^T b subject to lo <= b <= hi: ``_box_qp`` of keyframes.py, compiled.

    Plain loops only (module docstring: compile time); the free block's system by Cholesky (g's
    principal submatrices are positive definite as g is) where the reference calls np.linalg.solve."""
    n = f.shape[0]
    b = np.empty(n)
    held = np.zeros(n, dtype=np.bool_)
    eps = 1e-12 * (hi - lo)
    for i in range(n):
        b[i] = min(max(start[i], lo), hi)
    for i in range(n):
        grad = -f[i]
        for j in range(n):
            grad += g[i, j] * b[j]
        held[i] = (b[i] <= lo and grad >= 0) or (b[i] >= hi and grad <= 0)
        if held[i] and b[i] <= lo:
            b[i] = lo
        if held[i] and b[i] >= hi:
            b[i] = hi
    fmax = 0.0
    for i in range(n):
        fmax = max(fmax, abs(f[i]))
    limit = tol * max(1.0, fmax)
    free = np.empty(n, dtype=np.int64)
    chol = np.empty((n, n))  # the free block's lower Cholesky factor
    target = np.empty(n)
    room = np.empty(n)
    nb = np.empty(n)
    for _ in range(iterations):
        nf = 0
        for i in range(n):
            if not held[i]:
                free[nf] = i
                nf += 1
        if nf > 0:
            for a in range(nf):  # right-hand side f_free - g_free,held b_held
                s = f[free[a]]
                for c in range(n):
                    if held[c]:
                        s -= g[free[a], c] * b[c]
                target[a] = s
            for a in range(nf):
                for c in range(a + 1):
                    s = g[free[a], free[c]]
                    for m in range(c):
                        s -= chol[a, m] * chol[c, m]
                    chol[a, c] = np.sqrt(s) if a == c else s / chol[c, c]
            for a in range(nf):  # L y = rhs, then L^T target = y, in place
                s = target[a]
                for m in range(a):
                    s -= chol[a, m] * target[m]
                target[a] = s / chol[a, a]
            for a in range(nf - 1, -1, -1):
                s = target[a]
                for m in range(a + 1, nf):
                    s -= chol[m, a] * target[m]
                target[a] = s / chol[a, a]
            outside = False
            for a in range(nf):
                if target[a] < lo - eps or target[a] > hi + eps:
                    outside = True
            if outside:
                # Step towards the subspace minimiser until the first bound; hold what it hits.
                alpha = np.inf
                for a in range(nf):
                    d = target[a] - b[free[a]]
                    if d < 0:
                        room[a] = (lo - b[free[a]]) / d
                    elif d > 0:
                        room[a] = (hi - b[free[a]]) / d
                    else:
                        room[a] = np.inf
                    alpha = min(alpha, room[a])
                alpha = min(max(alpha, 0.0), 1.0)
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
        k = 0
        best = -np.inf
        for i in range(n):
            grad = -f[i]
            for j in range(n):
                grad += g[i, j] * b[j]
            p = 0.0
            if held[i] and b[i] <= lo:
                p = -grad
            elif held[i] and b[i] >= hi:
                p = grad
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
    f = np.empty(p)
    for i in range(p):
        acc = 0.0
        for k in range(x.shape[0]):
            acc += cross[i, k] * x[k]
        f[i] = acc
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
