"""Numba-compiled per-frame steps of the audio front end (``FrontEnd(..., kernel="numba")``).

Why compiled: a live push is one video frame, and the front end's numpy code spends most of it in
some forty calls on vectors of 12..1025 values (power spectrum, mel energies, log, DCT, the
running CMVN's per-frame update, context stacking). A live push is three calls: :func:`frames_push`
(pre-emphasis, buffer, framing, window, on preallocated state), numpy's FFT (numba has none), then
:func:`spectrum_to_ceps`; and :func:`normalise_stack` (silence gate, CMVN, context stacking, and the frames' levels
for the output noise gate) when the front end has no level normalisation. Each does the reference's arithmetic in
the same order. Fewer calls matter more than the arithmetic here: inside the live loop the inverter's matrices evict the
caches every frame, and each numpy call then costs several times what it costs timed alone (see
:mod:`realtime_core.inversion.compiled`). The numpy code (``kernel="numpy"``) is the reference;
tests/realtime_core/features/test_compiled.py holds the two equal to rounding.

Compiled lazily on first use and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def spectrum_to_ceps(  # pragma: no cover - compiled
    spec: np.ndarray,
    scale: float,
    fb_bins: np.ndarray,
    fb_weights: np.ndarray,
    fb_offsets: np.ndarray,
    floor: float,
    dct: np.ndarray,
) -> np.ndarray:
    """``(k, n_bins)`` complex spectra -> ``(k, n_out)`` cepstra: power ``|X|^2 * scale``, mel
    energies ``power @ fbank`` floored at ``floor``, log, then ``@ dct``.

    The filterbank comes sparse (:func:`sparse_filterbank`): filter m's nonzero weights are
    ``fb_weights[fb_offsets[m]:fb_offsets[m + 1]]`` on bins ``fb_bins[...]``, some 2,000 values
    instead of the dense 1025 x 26 matrix (16 KB instead of 213 KB of cache per frame)."""
    k, nb = spec.shape
    n_mels = fb_offsets.shape[0] - 1
    power = np.empty(nb)
    logmel = np.empty((k, n_mels))
    for i in range(k):
        for j in range(nb):
            z = spec[i, j]
            power[j] = (z.real * z.real + z.imag * z.imag) * scale
        for mm in range(n_mels):
            e = 0.0
            for q in range(fb_offsets[mm], fb_offsets[mm + 1]):
                e += power[fb_bins[q]] * fb_weights[q]
            logmel[i, mm] = np.log(max(e, floor))
    return np.dot(logmel, dct)


def sparse_filterbank(fbank: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense ``(n_bins, n_mels)`` filterbank -> ``(bins, weights, offsets)`` for :func:`spectrum_to_ceps`."""
    cols = [np.flatnonzero(fbank[:, m]) for m in range(fbank.shape[1])]
    bins = np.concatenate(cols).astype(np.int64)
    weights = np.concatenate([fbank[c, m] for m, c in enumerate(cols)])
    offsets = np.concatenate([[0], np.cumsum([c.size for c in cols])]).astype(np.int64)
    return bins, weights, offsets


@njit(cache=True, nogil=True)
def cmvn_push(  # pragma: no cover - compiled
    x: np.ndarray,
    lv: np.ndarray,
    m: np.ndarray,
    v: np.ndarray,
    c: float,
    gate_db: float,
    max_frames: float,
    var_floor: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The running CMVN over ``x (k, d)`` with levels ``lv (k,)`` from state ``(m (d,), v (d,), c)``.

    Returns ``(out (k, d), m, v, c)``: exactly :meth:`RunningCmvn.push`'s loop (update on frames at or
    above ``gate_db``, then normalise with the updated statistics)."""
    k, d = x.shape
    out = np.empty((k, d))
    m = m.copy()
    v = v.copy()
    for i in range(k):
        if lv[i] >= gate_db:
            c = min(c + 1.0, max_frames)
            a = 1.0 / c
            for j in range(d):
                dd = x[i, j] - m[j]
                m[j] = m[j] + a * dd
                v[j] = (1.0 - a) * (v[j] + a * dd * dd)
        for j in range(d):
            out[i, j] = (x[i, j] - m[j]) / np.sqrt(v[j] + var_floor)
    return out, m, v, c


@njit(cache=True, nogil=True)
def frames_push(  # pragma: no cover - compiled
    x: np.ndarray,
    buf: np.ndarray,
    ist: np.ndarray,
    last: np.ndarray,
    coef: float,
    rate: int,
    fps: int,
    window: np.ndarray,
    final: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """The framing half of ``MfccStream.push`` / ``flush`` (the numpy methods are the reference):
    pre-emphasise samples ``x (n,)`` float64 onto the buffer ``buf[:ist[0]]`` (which holds the samples
    from absolute index ``ist[1]``), then cut every frame now complete (with ``final``: every frame
    starting before the end, zero-padded) and multiply it by the window ``(win,)``.

    ist ``[n_buf, buf_start, n_received, next_frame]`` int64 and last ``[previous sample]`` float64 are
    the stream's state, updated in place. Returns ``(frames (k, win), buf)``: buf is the same array,
    or a larger one when it had to grow (the caller keeps it)."""
    n_buf, buf_start, n_received, nxt = ist[0], ist[1], ist[2], ist[3]
    win = window.shape[0]
    nx = x.shape[0]
    if n_buf + nx + win > buf.shape[0]:  # room for the samples and a final zero-padded frame
        grown = np.zeros(2 * (n_buf + nx + win))
        grown[:n_buf] = buf[:n_buf]
        buf = grown
    if nx:
        prev = last[0]
        for i in range(nx):
            buf[n_buf + i] = x[i] - coef * prev
            prev = x[i]
        last[0] = x[nx - 1]
        n_buf += nx
        n_received += nx
    k = nxt
    while True:
        s = (k * rate) // fps
        if final:
            if s >= n_received:
                break
        elif s + win > n_received:
            break
        k += 1
    frames = np.empty((k - nxt, win))
    for i in range(k - nxt):
        s = ((nxt + i) * rate) // fps - buf_start
        for j in range(win):
            # past the buffered samples (only on flush): zeros
            v = buf[s + j] if s + j < n_buf else 0.0
            frames[i, j] = v * window[j]
    drop = min((k * rate) // fps - buf_start, n_buf)
    if drop > 0:
        for i in range(n_buf - drop):
            buf[i] = buf[drop + i]
        n_buf -= drop
        buf_start += drop
    ist[0], ist[1], ist[2], ist[3] = n_buf, buf_start, n_received, k
    return frames, buf


@njit(cache=True, nogil=True)
def normalise_stack(  # pragma: no cover - compiled
    c0_ceps: np.ndarray,
    db_per_c0: float,
    floor_db: float,
    silence: np.ndarray,
    energy: bool,
    has_cmvn: bool,
    m: np.ndarray,
    v: np.ndarray,
    cst: np.ndarray,
    gate_db: float,
    max_frames: float,
    var_floor: float,
    ring: np.ndarray,
    cist: np.ndarray,
    tc: int,
    final: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """The front end after the MFCCs, for ``level_norm=None`` (the numpy reference: ``_LevelStage``,
    :class:`RunningCmvn` and :class:`ContextStacker`): raw ``[c0, c1..] (k, n_ceps + 1)`` -> the
    context-stacked rows now final ``(j, (2 tc + 1) n_feat)``; with ``final``, then the utterance's
    last rows (the stacker's flush).

    Level ``c0 * db_per_c0``; frames under ``floor_db`` (-inf: no gate) become ``silence``; c0 dropped
    unless ``energy``; the running CMVN (state m, v ``(n_feat,)`` and ``cst = [count]``, in place) unless
    not ``has_cmvn``; then context stacking on the ring ``(2 tc + 1, n_feat)`` of the last frames (slot i
    holds frame ``n - 2 tc - 1 + i``, clipped at frame 0: the first frame fills every slot) with
    ``cist = [frames received, next row]``, in place.

    Returns ``(rows, levels (k,))``: the levels (dB) of the k frames before the gate, the silence gate's own (the
    output noise gate reads them; numpy recomputed them from c0 on every live push)."""
    k = c0_ceps.shape[0]
    w, d = ring.shape
    first = 0 if energy else 1
    n, nxt = cist[0], cist[1]
    out = np.empty((k + (tc if final else 0), w * d))
    n_out = 0
    c = cst[0]
    row = np.empty(d)
    levels = np.empty(k)
    for i in range(k):
        level = c0_ceps[i, 0] * db_per_c0
        levels[i] = level
        if level < floor_db:
            for q in range(d):
                row[q] = silence[first + q]
        else:
            for q in range(d):
                row[q] = c0_ceps[i, first + q]
        if has_cmvn:
            if level >= gate_db:
                c = min(c + 1.0, max_frames)
                a = 1.0 / c
                for q in range(d):
                    dd = row[q] - m[q]
                    m[q] = m[q] + a * dd
                    v[q] = (1.0 - a) * (v[q] + a * dd * dd)
            for q in range(d):
                row[q] = (row[q] - m[q]) / np.sqrt(v[q] + var_floor)
        if n == 0:
            for s in range(w):
                ring[s, :] = row
        else:
            for s in range(w - 1):
                ring[s, :] = ring[s + 1, :]
            ring[w - 1, :] = row
        n += 1
        if n - 1 - tc >= nxt:  # row n - 1 - tc has its lookahead
            out[n_out] = ring.ravel()
            n_out += 1
            nxt += 1
    if final and n > 0:  # frames past the end repeat the last one
        for j in range(1, tc + 1):
            for s in range(w - 1):
                ring[s, :] = ring[s + 1, :]
            if n + j - 1 - tc >= nxt:  # the row this virtual frame completes
                out[n_out] = ring.ravel()
                n_out += 1
                nxt += 1
    cst[0] = c
    cist[0], cist[1] = n, nxt
    return out[:n_out], levels
