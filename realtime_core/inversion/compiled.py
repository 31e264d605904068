"""Numba-compiled per-frame kernels of the streaming inverter (``StreamConfig(kernel="numba")``).

Why compiled: at the sizes of a live model (N x M = 48..140 components, 77..88 audio dims, 4 visual
dims) one frame of :class:`realtime_core.inversion.StreamingInverter` is two matrix-vector products
plus some thirty small numpy calls; the calls, not the arithmetic, were most of the per-frame cost
(``facecast bench core``). Each kernel here is one call doing exactly what the numpy methods
``_forward`` / ``_combine`` do, in the same order and the same dtypes: the big products still go
through BLAS (``np.dot``), the rest are plain loops. The numpy methods stay the reference; the tests
hold the two equal to rounding (tests/realtime_core/inversion/test_compiled.py).

Compiled lazily on first use and cached next to this file (``cache=True``), so importing this module
costs numba's import only.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def forward_step(  # pragma: no cover - compiled
    row: np.ndarray,
    center: np.ndarray,
    quad: np.ndarray,
    const: np.ndarray,
    i0: np.ndarray,
    i1: np.ndarray,
    feat: np.ndarray,
    A: np.ndarray,
    prev: np.ndarray,
    has_prev: bool,
    start: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One frame of ``StreamingInverter._forward``.

    row ``(Da,)`` float64; center ``(Da,)`` and quad ``(C, K)`` in the plan's dtype; const ``(N, M)``;
    i0, i1 ``(K - Da,)`` upper-triangle indices; feat ``(K,)`` scratch; A ``(N, N)``; prev ``(N,)``
    the previous filtered posterior (ignored unless ``has_prev``); start ``(N,)``.
    Returns ``(f (N,), b (N,), mix (N, M), a (Da,))`` as the numpy method does.
    """
    a = row.astype(center.dtype) - center
    nq = i0.shape[0]
    da = a.shape[0]
    for k in range(nq):
        feat[k] = a[i0[k]] * a[i1[k]]
    for k in range(da):
        feat[nq + k] = a[k]
    lin = np.dot(quad, feat)
    n, m = const.shape
    logc = np.empty((n, m))
    top = -np.inf
    for j in range(n):
        for k in range(m):
            v = lin[j * m + k] + const[j, k]
            logc[j, k] = v
            if v > top:
                top = v
    b = np.empty(n)
    mix = np.empty((n, m))
    for j in range(n):
        s = 0.0
        for k in range(m):
            e = np.exp(logc[j, k] - top)
            mix[j, k] = e
            s += e
        b[j] = s
        d = max(s, 1e-300)
        for k in range(m):
            mix[j, k] /= d
    f = np.empty(n)
    total = 0.0
    if has_prev:
        for i in range(n):
            p = 0.0
            for j in range(n):
                p += prev[j] * A[j, i]
            f[i] = p * b[i]
            total += f[i]
    else:
        for i in range(n):
            f[i] = start[i] * b[i]
            total += f[i]
    if not total > 0:  # every state impossible: restart the filter from the prior
        bs = 0.0
        for i in range(n):
            bs += b[i]
        for i in range(n):
            f[i] = b[i] / bs
    else:
        for i in range(n):
            f[i] /= total
    return f, b, mix, a


@njit(cache=True, nogil=True)
def combine_step(  # pragma: no cover - compiled
    state_post: np.ndarray, mix: np.ndarray, a: np.ndarray, G: np.ndarray, h: np.ndarray, phi_flat: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Eq. 7 for one frame, as ``StreamingInverter._combine`` before its output stage.

    state_post ``(N,)``, mix ``(N, M)``, a ``(Da,)`` centred audio (plan dtype); G ``(C, Dv*Da)``,
    h ``(C, Dv)``, phi_flat ``(C, Dv*Dv)``. Returns ``(x (Dv,), ok)``: ``ok`` False when the
    weighted precision is not positive definite (the caller then solves by least squares).
    """
    n, m = mix.shape
    c = n * m
    r = np.empty(c)
    s = 0.0
    for j in range(n):
        for k in range(m):
            v = state_post[j] * mix[j, k]
            r[j * m + k] = v
            s += v
    for i in range(c):
        r[i] /= s
    dv = h.shape[1]
    da = a.shape[0]
    P = np.dot(r, phi_flat).reshape(dv, dv)
    Gr = np.dot(r.astype(G.dtype), G).reshape(dv, da)
    rhs = np.dot(Gr, a).astype(np.float64) + np.dot(r, h)
    # Cholesky P = L L^T, then two triangular solves (Dv is 4: loops beat any call).
    L = np.zeros((dv, dv))
    for i in range(dv):
        for j in range(i + 1):
            acc = P[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            if i == j:
                if not acc > 0:
                    return rhs, False
                L[i, i] = np.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    y = np.empty(dv)
    for i in range(dv):
        acc = rhs[i]
        for k in range(i):
            acc -= L[i, k] * y[k]
        y[i] = acc / L[i, i]
    x = np.empty(dv)
    for i in range(dv - 1, -1, -1):
        acc = y[i]
        for k in range(i + 1, dv):
            acc -= L[k, i] * x[k]
        x[i] = acc / L[i, i]
    return x, True


@njit(cache=True, nogil=True)
def filter_rows(  # pragma: no cover - compiled
    oa: np.ndarray,
    center: np.ndarray,
    quad: np.ndarray,
    const: np.ndarray,
    i0: np.ndarray,
    i1: np.ndarray,
    feat: np.ndarray,
    A: np.ndarray,
    prev: np.ndarray,
    has_prev: bool,
    start: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    phi_flat: np.ndarray,
    out: np.ndarray,
    post: np.ndarray,
) -> tuple[np.ndarray, int]:
    """Lag 0 (pure filtering) over rows ``oa (k, Da)``: :func:`forward_step` then :func:`combine_step`
    per row into ``out (k, Dv)`` (and the normalised component posteriors into ``post (k, N*M)``, for
    the readout, unless it has 0 rows), in one call. Returns ``(f, stop)``: the filtered posterior after
    the rows done and ``stop = -1``, or, at a row whose weighted precision is not positive definite, the
    posterior before that row and its index (the caller finishes from there with the row-wise path)."""
    f = prev
    for t in range(oa.shape[0]):
        f_new, _, mix, a = forward_step(oa[t], center, quad, const, i0, i1, feat, A, f, has_prev or t > 0, start)
        x, ok = combine_step(f_new, mix, a, G, h, phi_flat)
        if not ok:
            return f, t
        out[t] = x
        if post.shape[0]:
            n, m = mix.shape
            s = 0.0
            for j in range(n):
                for k in range(m):
                    s += f_new[j] * mix[j, k]
            for j in range(n):
                for k in range(m):
                    post[t, j * m + k] = f_new[j] * mix[j, k] / s
        f = f_new
    return f, -1


@njit(cache=True, nogil=True)
def readout_step(  # pragma: no cover - compiled
    raw: np.ndarray,
    component_post: np.ndarray,
    audio: np.ndarray,
    phi: np.ndarray,
    started: bool,
    taps: int,
    a0: int,
    a1: int,
    post_kind: int,
    n_mix: int,
    w1: np.ndarray,
    b1: np.ndarray,
    w2: np.ndarray,
    b2: np.ndarray,
) -> np.ndarray:
    """One frame of ``realtime_core.readout.ReadoutStream.step`` (the numpy method is the reference).

    phi ``(F,)`` float64: the stream's feature vector, updated in place (taps shifted, audio ``phi[a0:a1]``,
    posteriors ``phi[a1:]``); post_kind 0 none, 1 state (summed over the ``n_mix`` mixtures), 2 component.
    w1 ``(F, H)``, b1 ``(H,)``, w2 ``(H or F, Dv)``, b2 ``(Dv,)``; H = 0 is a linear map. Returns ``(Dv,)``."""
    dv = raw.shape[0]
    if started:
        for k in range(taps - 1, 0, -1):
            for i in range(dv):
                phi[k * dv + i] = phi[(k - 1) * dv + i]
    else:  # frames before the first repeat it
        for k in range(1, taps):
            for i in range(dv):
                phi[k * dv + i] = raw[i]
    for i in range(dv):
        phi[i] = raw[i]
    for i in range(a1 - a0):
        phi[a0 + i] = audio[i]
    if post_kind == 1:
        for j in range(phi.shape[0] - a1):
            s = 0.0
            for k in range(n_mix):
                s += component_post[j * n_mix + k]
            phi[a1 + j] = s
    elif post_kind == 2:
        for j in range(phi.shape[0] - a1):
            phi[a1 + j] = component_post[j]
    if b1.shape[0] > 0:
        hid = np.dot(phi, w1) + b1
        for i in range(hid.shape[0]):
            if hid[i] < 0.0:
                hid[i] = 0.0
        return np.dot(hid, w2) + b2
    return np.dot(phi, w2) + b2
