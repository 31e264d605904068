"""Numba-compiled per-frame steps of the audio front end (``FrontEnd(..., kernel="numba")``).

Why compiled: a live push is one video frame, and the front end's numpy code spends most of it in
some forty calls on vectors of 12..1025 values (power spectrum, mel energies, log, DCT, the
running CMVN's per-frame update); one compiled call each for the spectrum-to-cepstra step and the
CMVN step does the same arithmetic in the same order. The FFT stays numpy's (numba has none). The
numpy code (``kernel="numpy"``) is the reference; tests/realtime_core/features/test_compiled.py
holds the two equal to rounding.

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
