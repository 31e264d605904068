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
    spec: np.ndarray, scale: float, fbank: np.ndarray, floor: float, dct: np.ndarray
) -> np.ndarray:
    """``(k, n_bins)`` complex spectra -> ``(k, n_out)`` cepstra: power ``|X|^2 * scale``, mel
    energies ``power @ fbank`` floored at ``floor``, log, then ``@ dct``."""
    k, nb = spec.shape
    power = np.empty((k, nb))
    for i in range(k):
        for j in range(nb):
            z = spec[i, j]
            power[i, j] = (z.real * z.real + z.imag * z.imag) * scale
    energies = np.dot(power, fbank)
    for i in range(k):
        for j in range(energies.shape[1]):
            energies[i, j] = np.log(max(energies[i, j], floor))
    return np.dot(energies, dct)


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
