"""Numba-compiled per-frame kernels of the streaming inverter (``StreamConfig(kernel="numba")``).

Why compiled: at the sizes of a live model (N x M = 48..140 components, 77..88 audio dims, 4 visual
dims) one frame of :class:`realtime_core.inversion.StreamingInverter` is two matrix-vector products
plus some thirty small numpy calls; the calls, not the arithmetic, were most of the per-frame cost
(``facecast bench core``). Each kernel here is one call doing what the numpy methods ``_forward`` /
``_raw`` (and, for the readout and the output stage, :class:`realtime_core.readout.ReadoutStream` and
:class:`realtime_core.output.OutputStage`) do: the likelihood product still goes through BLAS
(``np.dot``), the rest are plain loops. At lag 0 (the live case) :func:`filter_rows` runs a whole push
- forward step, component posteriors (once, shared by eq. 7 and the readout), eq. 7, readout, output
stage - in one call on the session's state arrays, so no per-frame Python sits between the stages.

Why it matters beyond the call count: on this machine the live path is bound by cache misses. The
likelihood matrix (1.7 MB at N=28, M=5 in float32) streams through the 2 MB L2 every frame and evicts
everything else, so each numpy call after it ran several times slower than timed alone (the front end
took 41 us alone and 88 us inside the live loop). Fewer calls and less memory touched per frame
(components under ``SKIP_POSTERIOR`` skipped) is what cut the live path, not faster arithmetic.

The numpy methods stay the reference; the tests hold the two equal to rounding
(tests/realtime_core/inversion/test_compiled.py).

Compiled lazily on first use and cached next to this file (``cache=True``), so importing this module
costs numba's import only.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from realtime_core.inversion.stream import SKIP_POSTERIOR


@njit(cache=True, nogil=True)
def forward_step(  # pragma: no cover - compiled
    row: np.ndarray,
    center: np.ndarray,
    quad: np.ndarray,
    const: np.ndarray,
    feat: np.ndarray,
    A: np.ndarray,
    prev: np.ndarray,
    has_prev: bool,
    start: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One frame of ``StreamingInverter._forward``.

    row ``(Da,)`` float64; center ``(Da,)`` and quad ``(C, K)`` in the plan's dtype; const ``(N, M)``;
    feat ``(K,)`` scratch, filled with ``[a_i a_j (i <= j, row-major as np.triu_indices); a]``;
    A ``(N, N)``; prev ``(N,)`` the previous filtered posterior (ignored unless ``has_prev``);
    start ``(N,)``. Returns ``(f (N,), b (N,), mix (N, M), a (Da,))`` as the numpy method does.
    """
    a = row.astype(center.dtype) - center
    da = a.shape[0]
    q = 0
    for i in range(da):  # the upper triangle row by row: no index arrays to read
        ai = a[i]
        for j in range(i, da):
            feat[q] = ai * a[j]
            q += 1
    for k in range(da):
        feat[q + k] = a[k]
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
def component_posteriors(state_post: np.ndarray, mix: np.ndarray, r: np.ndarray) -> None:  # pragma: no cover
    """``(N,)`` state and ``(N, M)`` within-state posteriors -> the normalised component posteriors,
    written into ``r (N*M,)`` (``stream._component_posteriors``)."""
    n, m = mix.shape
    s = 0.0
    for j in range(n):
        for k in range(m):
            v = state_post[j] * mix[j, k]
            r[j * m + k] = v
            s += v
    for i in range(n * m):
        r[i] /= s


@njit(cache=True, nogil=True)
def eq7(  # pragma: no cover - compiled
    r: np.ndarray, a: np.ndarray, G: np.ndarray, h: np.ndarray, phi_flat: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Eq. 7 for one frame from its component posteriors ``r (C,)`` and centred audio ``a (Da,)``
    (plan dtype); G ``(C, Dv*Da)``, h ``(C, Dv)``, phi_flat ``(C, Dv*Dv)``. Returns ``(x (Dv,), ok)``:
    ``ok`` False when the weighted precision is not positive definite (the caller then solves by least
    squares; x is then the right-hand side).

    The sums over components run in float64 over those with ``r >= SKIP_POSTERIOR`` only (a live
    frame has a dozen or so): G's float32 entries convert exactly, so the sum is the reference's
    ``r @ G`` in float64 to rounding, with ~10x fewer of G's rows read."""
    c = r.shape[0]
    dv = h.shape[1]
    da = a.shape[0]
    nd = dv * da
    P = np.zeros(dv * dv)
    Gr = np.zeros(nd)
    rhs = np.zeros(dv)
    for i in range(c):
        ri = r[i]
        if ri < SKIP_POSTERIOR:
            continue
        for q in range(dv * dv):
            P[q] += ri * phi_flat[i, q]
        for q in range(nd):
            Gr[q] += ri * G[i, q]
        for q in range(dv):
            rhs[q] += ri * h[i, q]
    for q in range(dv):
        acc = 0.0
        for k in range(da):
            acc += Gr[q * da + k] * a[k]
        rhs[q] += acc
    # Cholesky P = L L^T, then two triangular solves (Dv is 4: loops beat any call).
    L = np.zeros((dv, dv))
    for i in range(dv):
        for j in range(i + 1):
            acc = P[i * dv + j]
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
def combine_step(  # pragma: no cover - compiled
    state_post: np.ndarray, mix: np.ndarray, a: np.ndarray, G: np.ndarray, h: np.ndarray, phi_flat: np.ndarray
) -> tuple[np.ndarray, bool]:
    """Eq. 7 for one frame, as ``StreamingInverter._raw``: state_post ``(N,)``, mix ``(N, M)``, then
    :func:`eq7`."""
    r = np.empty(mix.shape[0] * mix.shape[1])
    component_posteriors(state_post, mix, r)
    return eq7(r, a, G, h, phi_flat)


@njit(cache=True, nogil=True)
def output_step(x: np.ndarray, floor: np.ndarray, band: float, knee: float) -> None:  # pragma: no cover
    """``realtime_core.output.OutputStage`` on one frame ``x (Dv,)``, in place: the closure band
    (``band`` > 0, parameters with a finite ``floor``), then the floor."""
    gain = knee / (knee - 1.0)
    for j in range(x.shape[0]):
        c = floor[j]
        v = max(x[j], c)
        if band > 0.0 and np.isfinite(c) and v < c + knee * band:
            v = c + max(v - c - band, 0.0) * gain
        x[j] = v


@njit(cache=True, nogil=True)
def filter_rows(  # pragma: no cover - compiled
    oa: np.ndarray,
    center: np.ndarray,
    quad: np.ndarray,
    const: np.ndarray,
    feat: np.ndarray,
    A: np.ndarray,
    prev: np.ndarray,
    has_prev: bool,
    start: np.ndarray,
    G: np.ndarray,
    h: np.ndarray,
    phi_flat: np.ndarray,
    out: np.ndarray,
    ro_phi: np.ndarray,
    ro_started: bool,
    ro_sizes: np.ndarray,
    ro_w1: np.ndarray,
    ro_b1: np.ndarray,
    ro_w2: np.ndarray,
    ro_b2: np.ndarray,
    floor: np.ndarray,
    band: float,
    knee: float,
) -> tuple[np.ndarray, int]:
    """The whole lag-0 inverter over rows ``oa (k, Da)`` in one call: per row :func:`forward_step`,
    the component posteriors (once), :func:`eq7`, the learned readout (:func:`readout_step`, unless
    ``ro_phi`` has 0 entries; ``ro_sizes`` = ``[taps, a0, a1, post_kind, n_mix]``) and the output
    stage (:func:`output_step`, unless ``floor`` has 0 entries), into ``out (k, Dv)``.

    Returns ``(f, stop)``: the filtered posterior after the rows done and ``stop = -1``, or, at a row
    whose weighted precision is not positive definite, the posterior before that row and its index
    (the caller finishes from there with the row-wise path)."""
    f = prev
    n, m = const.shape
    r = np.empty(n * m)
    started = ro_started
    for t in range(oa.shape[0]):
        f_new, _, mix, a = forward_step(oa[t], center, quad, const, feat, A, f, has_prev or t > 0, start)
        component_posteriors(f_new, mix, r)
        x, ok = eq7(r, a, G, h, phi_flat)
        if not ok:
            return f, t
        if ro_phi.shape[0]:
            x = readout_step(
                x, r, a, ro_phi, started, ro_sizes[0], ro_sizes[1], ro_sizes[2], ro_sizes[3], ro_sizes[4],
                ro_w1, ro_b1, ro_w2, ro_b2,
            )  # fmt: skip
            started = True
        if floor.shape[0]:
            output_step(x, floor, band, knee)
        out[t] = x
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
    # Both layers as loops over the inputs (rows of w1 and w2 are contiguous): inputs under
    # SKIP_POSTERIOR in size (most posterior features, units the ReLU zeroed) are skipped.
    nh = b1.shape[0]
    w_out = w2 if nh == 0 else w1
    acc = np.zeros(w_out.shape[1])
    for i in range(phi.shape[0]):
        v = phi[i]
        if abs(v) < SKIP_POSTERIOR:
            continue
        for k in range(acc.shape[0]):
            acc[k] += v * w_out[i, k]
    if nh == 0:
        return acc + b2
    y = np.zeros(dv)
    for i in range(nh):
        v = acc[i] + b1[i]
        if v > 0.0:
            for k in range(dv):
                y[k] += v * w2[i, k]
    return y + b2
