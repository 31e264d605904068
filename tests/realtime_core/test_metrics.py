"""Metrics against independent computations (scipy.stats, direct formulas)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats

from realtime_core.metrics import acc, amse, normalised_mse, pearson_per_param, pearson_r_trace


def test_metrics_match_independent_formulas():
    rng = np.random.default_rng(0)
    true = rng.standard_normal((300, 4)) * [1, 2, 3, 4]
    est = true * 0.7 + rng.standard_normal((300, 4))
    r = [scipy.stats.pearsonr(true[:, i], est[:, i])[0] for i in range(4)]
    np.testing.assert_allclose(pearson_per_param(true, est), r, rtol=1e-12)
    assert acc(true, est) == pytest.approx(np.mean(r))
    assert amse(true, est) == pytest.approx(
        np.mean([np.mean((est[:, i] - true[:, i]) ** 2) / true[:, i].var() for i in range(4)])
    )
    assert amse(true, true) == 0.0 and acc(true, true) == pytest.approx(1.0)
    flat_t, flat_e = (true - true.mean(0)).ravel(), (est - est.mean(0)).ravel()
    assert pearson_r_trace(true, est) == pytest.approx(flat_t @ flat_e / np.sqrt(flat_t @ flat_t * (flat_e @ flat_e)))
    s = np.abs(true).max(axis=0)
    assert normalised_mse(true, est) == pytest.approx(np.mean(((true - est) / s) ** 2))
