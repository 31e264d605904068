"""Accuracy metrics of estimated visual parameters.

Paper 000: AMSE (eq. 11) and ACC (eq. 12). Paper 002: Pearson R (eq. 6) and MSE (eq. 8),
computed on data normalised to [-1, 1] by each parameter's maximum absolute value.
All take ``true`` and ``est`` of shape ``(T, R)`` (T frames, R parameters).
"""

from __future__ import annotations

import numpy as np

from realtime_core.errors import InvalidFeaturesError


def _pair(true: np.ndarray, est: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(true, dtype=np.float64)
    e = np.asarray(est, dtype=np.float64)
    if t.ndim == 1:
        t, e = t[:, None], e.reshape(-1, 1)
    if t.shape != e.shape or t.ndim != 2 or t.shape[0] < 2:
        raise InvalidFeaturesError(
            f"true and estimated tracks must be equal (T >= 2, R) shapes, got {t.shape}, {e.shape}"
        )
    return t, e


def amse(true: np.ndarray, est: np.ndarray) -> float:
    """Eq. 11: ``1/(R T) sum_r sum_t (est - true)^2 / var_r(true)``."""
    t, e = _pair(true, est)
    var = t.var(axis=0)
    var = np.where(var > 0, var, 1.0)
    return float(np.mean(((e - t) ** 2).mean(axis=0) / var))


def pearson_per_param(true: np.ndarray, est: np.ndarray) -> np.ndarray:
    """Pearson r of each column, ``(R,)``; 0 where either track is constant."""
    t, e = _pair(true, est)
    tc, ec = t - t.mean(axis=0), e - e.mean(axis=0)
    den = np.sqrt((tc**2).sum(axis=0) * (ec**2).sum(axis=0))
    return np.where(den > 0, (tc * ec).sum(axis=0) / np.where(den > 0, den, 1.0), 0.0)


def acc(true: np.ndarray, est: np.ndarray) -> float:
    """Eq. 12: the average over parameters of the correlation coefficient."""
    return float(np.mean(pearson_per_param(true, est)))


def pearson_r_trace(true: np.ndarray, est: np.ndarray) -> float:
    """Paper 002 eq. 6: ``tr(Cov_dd') / sqrt(tr(Cov_dd) tr(Cov_d'd'))`` (vector Pearson R)."""
    t, e = _pair(true, est)
    tc, ec = t - t.mean(axis=0), e - e.mean(axis=0)
    den = np.sqrt((tc**2).sum() * (ec**2).sum())
    return float((tc * ec).sum() / den) if den > 0 else 0.0


def normalised_mse(true: np.ndarray, est: np.ndarray, *, scale: np.ndarray | None = None) -> float:
    """Paper 002 eq. 8 on data divided by ``scale`` (default: max |true| per parameter)."""
    t, e = _pair(true, est)
    s = np.abs(t).max(axis=0) if scale is None else np.asarray(scale, dtype=np.float64)
    s = np.where(s > 0, s, 1.0)
    return float(np.mean(((t - e) / s) ** 2))


def average_std(x: np.ndarray) -> float:
    """Paper 002 eq. 7: ``nu = (1/gamma) sum_c sqrt(Cov[c][c])``, the mean per-dimension standard deviation
    of ``(T, gamma)``."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] < 2:
        raise InvalidFeaturesError(f"a track must be (T >= 2, gamma), got {a.shape}")
    return float(np.sqrt(a.var(axis=0)).mean())
