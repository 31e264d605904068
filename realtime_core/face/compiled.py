"""Numba-compiled bounded keyframe solve (``KeyframeMap.weights(..., kernel="numba")``), a morph head's vertex
frames, and, at rig time, the fold repair's measurement and the visibility search (the last four functions: each
the same float64 operations in the same order as the numpy it replaced, so the same rigs).

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


@njit(cache=True, nogil=True)
def lip_bounds_clear(  # pragma: no cover - compiled
    check: np.ndarray, limit: np.ndarray, b: np.ndarray, x: np.ndarray
) -> bool:
    """``KeyframeMap._apart_already`` in one call: ``check`` (3m, P + k) times [b (P,); x (k,)] minus
    ``limit`` (3m,), rows (floor, ceiling bound 1, ceiling bound 2) per lip column; True when every
    column's floor row and one of its two ceiling rows are at or under 0. In numpy the concatenation,
    product and reductions cost ~6 us per frame (the whole solve is ~8 us); this is well under 1 us."""
    m = limit.shape[0] // 3
    p = b.shape[0]
    r = np.empty(limit.shape[0])
    for i in range(limit.shape[0]):
        acc = -limit[i]
        for k in range(p):
            acc += check[i, k] * b[k]
        for k in range(x.shape[0]):
            acc += check[i, p + k] * x[k]
        r[i] = acc
    clear = True  # (a loop, not all(...) over a generator: plain code for numba)
    for j in range(m):
        clear = clear and r[j] <= 0.0 and (r[m + j] <= 0.0 or r[2 * m + j] <= 0.0)
    return clear


# Columns per block of the morph product: the block of all targets (P x 1024 float32, ~78 KB for the
# built-in head's 19) stays in L2 while every frame of the batch is computed over it.
MORPH_BLOCK = 1024


@njit(cache=True, nogil=True, boundscheck=False, fastmath={"contract"})
def _morph_block_one(w: np.ndarray, rows: np.ndarray, c0: int, c1: int, o: np.ndarray) -> None:  # pragma: no cover
    """o (c1 - c0,) = w (P,) @ rows[:, c0:c1], in the order of :func:`morph_displacements`. (Each target's
    block is sliced here from the C-contiguous ``rows``, so numba knows it contiguous and vectorises.)"""
    npt, m = rows.shape[0], c1 - c0
    for j in range(m):
        o[j] = np.float32(0.0)
    p = 0
    # Four targets per sweep (one load and store of ``o`` per four products); the sum keeps its order.
    while p + 4 <= npt:
        w0, w1, w2, w3 = w[p], w[p + 1], w[p + 2], w[p + 3]
        r0, r1, r2, r3 = rows[p, c0:c1], rows[p + 1, c0:c1], rows[p + 2, c0:c1], rows[p + 3, c0:c1]
        for j in range(m):
            o[j] = (((o[j] + w0 * r0[j]) + w1 * r1[j]) + w2 * r2[j]) + w3 * r3[j]
        p += 4
    while p < npt:
        wp, r = w[p], rows[p, c0:c1]
        for j in range(m):
            o[j] = o[j] + wp * r[j]
        p += 1


@njit(cache=True, nogil=True, boundscheck=False, fastmath={"contract"})
def _morph_block_two(  # pragma: no cover - compiled
    w: np.ndarray, v: np.ndarray, rows: np.ndarray, c0: int, c1: int, o: np.ndarray, u: np.ndarray
) -> None:
    """Two frames over one block: o = w @ rows[:, c0:c1], u = v @ rows[:, c0:c1], each element in the
    order of :func:`_morph_block_one` (so the same bits); every target value loaded once for both."""
    npt, m = rows.shape[0], c1 - c0
    for j in range(m):
        o[j] = np.float32(0.0)
        u[j] = np.float32(0.0)
    p = 0
    while p + 4 <= npt:
        w0, w1, w2, w3 = w[p], w[p + 1], w[p + 2], w[p + 3]
        v0, v1, v2, v3 = v[p], v[p + 1], v[p + 2], v[p + 3]
        r0, r1, r2, r3 = rows[p, c0:c1], rows[p + 1, c0:c1], rows[p + 2, c0:c1], rows[p + 3, c0:c1]
        for j in range(m):
            a0, a1, a2, a3 = r0[j], r1[j], r2[j], r3[j]
            o[j] = (((o[j] + w0 * a0) + w1 * a1) + w2 * a2) + w3 * a3
            u[j] = (((u[j] + v0 * a0) + v1 * a1) + v2 * a2) + v3 * a3
        p += 4
    while p < npt:
        wp, vp, r = w[p], v[p], rows[p, c0:c1]
        for j in range(m):
            a = r[j]
            o[j] = o[j] + wp * a
            u[j] = u[j] + vp * a
        p += 1


@njit(cache=True, nogil=True, boundscheck=False, fastmath={"contract"})
def morph_displacements(  # pragma: no cover - compiled
    w: np.ndarray, rows: np.ndarray, out: np.ndarray
) -> np.ndarray:
    """Several frames' morph-target displacements in one pass over the targets: ``out[b] = w[b] @ rows``.

    w (B, P) float32 target weights, rows (P, n) float32 targets flattened (``MorphRig._rows``), out
    (B, n) float32, written and returned. Why one pass: a server computes the deltas of every frame
    of a loop turn together, and frame by frame each product streams the 632 KB of the built-in
    head's targets again; here each block of columns is read once for all B frames (two frames per
    sweep of it, each target value loaded once for both).

    Every element is ``(((0 + w0 r0) + w1 r1) + ...) + w_{P-1} r_{P-1}`` in that order (fused
    multiply-adds allowed: ``fastmath={"contract"}`` only, no reassociation), whatever B, the block
    and whether the frame went alone or in a pair, so a frame's displacements are the same bits
    computed alone or in any batch; against numpy's product (BLAS, its own order) they agree to
    float32 rounding."""
    nb = w.shape[0]
    n = rows.shape[1]
    for c0 in range(0, n, MORPH_BLOCK):
        c1 = min(c0 + MORPH_BLOCK, n)
        b = 0
        while b + 2 <= nb:
            _morph_block_two(w[b], w[b + 1], rows, c0, c1, out[b, c0:c1], out[b + 1, c0:c1])
            b += 2
        if b < nb:
            _morph_block_one(w[b], rows, c0, c1, out[b, c0:c1])
    return out


@njit(cache=True, nogil=True, boundscheck=False)
def quantize_int16_rows(  # pragma: no cover - compiled
    values: np.ndarray, out: np.ndarray, scales: np.ndarray
) -> np.ndarray:
    """Each row of ``values`` (B, n) float32 to int16 with its own scale: ``scales[b]`` (float64) =
    max|row| / 32767 (1 for an all-zero row), ``out[b] = rint(row / float32(scale))``, round half to
    even. The same arithmetic step for step as the wire's int16 encoding (``wire.protocol.encode_payload``,
    numpy: abs, max, a float32 division, rint, a cast; tested byte-equal), in one pass per row
    instead of six over temporaries: a vertex frame of the built-in head ~14 -> ~7 us."""
    nb, n = values.shape
    magic = np.float32(12582912.0)  # 1.5 * 2**23: x + magic - magic rounds a float32 |x| <= 2**22 half-even
    for b in range(nb):
        v = values[b]
        q = out[b]
        peak = np.float32(0.0)
        for j in range(n):
            peak = max(peak, abs(v[j]))
        scale = np.float64(peak) / 32767.0 if peak > 0 else 1.0
        scales[b] = scale
        s = np.float32(scale)
        for j in range(n):
            q[j] = np.int16((v[j] / s + magic) - magic)
    return out


@njit(cache=True, nogil=True, boundscheck=False)
def morph_displacements_int16(  # pragma: no cover - compiled
    w: np.ndarray, rows: np.ndarray, values: np.ndarray, out: np.ndarray, scales: np.ndarray
) -> np.ndarray:
    """:func:`morph_displacements` into ``values`` (B, n) float32, then :func:`quantize_int16_rows` into
    ``out`` (B, n) int16 and ``scales`` (B,): the same two kernels in one call (a numba call with five
    arrays costs a few microseconds of argument checks, a tenth of a frame's work)."""
    morph_displacements(w, rows, values)
    return quantize_int16_rows(values, out, scales)


@njit(cache=True, nogil=True, boundscheck=False)
def flipped_at_poses(  # pragma: no cover - compiled
    v0: np.ndarray, disp: np.ndarray, triangles: np.ndarray, n0: np.ndarray, which: np.ndarray, out: np.ndarray
) -> None:
    """The fold repair's flip test (:class:`realtime_core.face.repair._FoldWatch`): for each triangle ``which`` (k,)
    int of ``triangles`` (m, 3) int64 and every pose p, ``out[f, p]`` = its normal at that pose points against its
    rest normal ``n0[f]`` (m, 3) float64: ``n0 . ((b - a) x (c - a)) < 0``, a vertex i at pose p at
    ``v0[i] + disp[i, 3p:3p+3]`` (v0 (n, 3), disp (n, 3 * n_poses) float64; out (m, n_poses) bool).

    The same float64 operations in the same order as the numpy it replaces (``np.cross``'s products and differences,
    then the dot product summed x, y, z), no fused multiply-add, so every decision is the same; one pass per triangle
    instead of a dozen (k, poses, 3) temporaries: the repair's measurement was most of a coarse head's rig time
    (a 4,500-triangle head's 3.6 min of rig tries, docs/animation.md "The repair's measurement compiled")."""
    n_poses = out.shape[1]
    for q in range(which.shape[0]):
        f = which[q]
        a, b, c = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        nx, ny, nz = n0[f, 0], n0[f, 1], n0[f, 2]
        for p in range(n_poses):
            o = 3 * p
            ax, ay, az = v0[a, 0] + disp[a, o], v0[a, 1] + disp[a, o + 1], v0[a, 2] + disp[a, o + 2]
            ux = (v0[b, 0] + disp[b, o]) - ax
            uy = (v0[b, 1] + disp[b, o + 1]) - ay
            uz = (v0[b, 2] + disp[b, o + 2]) - az
            wx = (v0[c, 0] + disp[c, o]) - ax
            wy = (v0[c, 1] + disp[c, o + 1]) - ay
            wz = (v0[c, 2] + disp[c, o + 2]) - az
            cx = uy * wz - uz * wy
            cy = uz * wx - ux * wz
            cz = ux * wy - uy * wx
            s = nx * cx
            s = s + ny * cy
            s = s + nz * cz
            out[f, p] = s < 0.0


@njit(cache=True, nogil=True, boundscheck=False)
def stretched_at_poses(  # pragma: no cover - compiled
    v0: np.ndarray,
    disp: np.ndarray,
    edges: np.ndarray,
    longest: np.ndarray,
    which: np.ndarray,
    n_poses: int,
    out: np.ndarray,
) -> None:
    """The fold repair's stretch test: for each edge ``which`` (k,) int of ``edges`` (E, 2) int64, ``out[e]`` =
    its length exceeds ``longest[e]`` (E,) float64 at any of the first ``n_poses`` poses (positions as in
    :func:`flipped_at_poses`; out (E,) bool). The length as ``np.linalg.norm`` computes it (the squares summed x, y,
    z, then the square root), so the same decisions."""
    for q in range(which.shape[0]):
        e = which[q]
        i, j = edges[e, 0], edges[e, 1]
        limit = longest[e]
        over = False
        for p in range(n_poses):
            o = 3 * p
            dx = (v0[i, 0] + disp[i, o]) - (v0[j, 0] + disp[j, o])
            dy = (v0[i, 1] + disp[i, o + 1]) - (v0[j, 1] + disp[j, o + 1])
            dz = (v0[i, 2] + disp[i, o + 2]) - (v0[j, 2] + disp[j, o + 2])
            s = dx * dx
            s = s + dy * dy
            s = s + dz * dz
            if np.sqrt(s) > limit:
                over = True
                break
        out[e] = over


@njit(cache=True, nogil=True, boundscheck=False, error_model="numpy")
def front_most_binned(  # pragma: no cover - compiled
    points: np.ndarray,
    tris: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    owner: np.ndarray,
    start: np.ndarray,
    stop: np.ndarray,
    skip: np.ndarray,
    below: np.ndarray,
    tolerance: float,
    out: np.ndarray,
) -> None:
    """The search of :func:`realtime_core.face.visibility.front_most` once its grid is built: for each point i of
    ``points`` (k, 2) float64, the triangles ``owner[start[i]:stop[i]]`` (int) of ``tris`` (m, 3, 3) float64 (u, w,
    depth) binned in its cell, but ``skip[i]`` (k,) int64 (-1: none), each tested as front_most tests it (barycentric
    coordinates as :func:`realtime_core.face.interpolation.barycentric_2d` computes them, within ``tolerance`` and
    within the triangle's box ``lo``/``hi`` (m, 2), depth under ``below[i]`` (k,) float64, inf for no limit):
    ``out[i]`` the largest depth found, NaN for none. The same float64 operations in the same order as the numpy
    (the depth summed over the three corners in order), so the same answers; a loop over each point's candidates
    instead of (pairs,)-long temporaries: the search was the rig checks' largest cost."""
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        best = -np.inf
        for q in range(start[i], stop[i]):
            f = owner[q]
            if f == skip[i]:
                continue
            if px < lo[f, 0] or py < lo[f, 1] or px > hi[f, 0] or py > hi[f, 1]:
                continue
            ax, ay = tris[f, 0, 0], tris[f, 0, 1]
            v0x, v0y = tris[f, 1, 0] - ax, tris[f, 1, 1] - ay
            v1x, v1y = tris[f, 2, 0] - ax, tris[f, 2, 1] - ay
            v2x, v2y = px - ax, py - ay
            den = v0x * v1y - v1x * v0y
            l1 = (v2x * v1y - v1x * v2y) / den
            l2 = (v0x * v2y - v2x * v0y) / den
            l0 = 1.0 - l1 - l2
            if not (np.isfinite(l0) and np.isfinite(l1) and np.isfinite(l2)):
                continue
            if l0 < -tolerance or l1 < -tolerance or l2 < -tolerance:
                continue
            depth = l0 * tris[f, 0, 2]
            depth = depth + l1 * tris[f, 1, 2]
            depth = depth + l2 * tris[f, 2, 2]
            if depth < below[i] and depth > best:
                best = depth
        out[i] = best if np.isfinite(best) else np.nan


@njit(cache=True, nogil=True, boundscheck=False)
def triangle_boxes(tris: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:  # pragma: no cover - compiled
    """``lo``, ``hi`` (m, 2) float64: the smallest and largest (u, w) of each triangle of ``tris`` (m, 3, 3) float64
    over its three corners (NaN where a corner's coordinate is NaN, as numpy's min and max give): what
    :func:`realtime_core.face.visibility.front_most` bins by, in one pass instead of two strided reductions."""
    for f in range(tris.shape[0]):
        for d in range(2):
            a, b, c = tris[f, 0, d], tris[f, 1, d], tris[f, 2, d]
            if np.isnan(a) or np.isnan(b) or np.isnan(c):
                lo[f, d] = np.nan
                hi[f, d] = np.nan
            else:
                lo[f, d] = min(a, b, c)
                hi[f, d] = max(a, b, c)
