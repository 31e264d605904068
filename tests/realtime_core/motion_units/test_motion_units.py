"""Motion Units: PCA against an independent SVD, eq. 1-2 identities, eq. 4 against lstsq."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ConfigError, InvalidFeaturesError
from realtime_core.motion_units import (
    KeyframeSet,
    analyse,
    compose,
    fit_expression_units,
    fit_motion_units,
    in_mu_space,
    keyframes_to_mups,
    mups_to_keyframes,
    round_trip_error,
)


def _data(n: int = 400, dim: int = 30, rank: int = 5, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    basis = rng.standard_normal((rank, dim))
    scales = np.array([3.0, 2.0, 1.0, 0.5, 0.25])[:rank]
    return (rng.standard_normal((n, rank)) * scales) @ basis + 0.01 * rng.standard_normal((n, dim)) + 0.3


def test_pca_matches_independent_svd() -> None:
    d = _data()
    mu = fit_motion_units(d, n_units=5)
    xc = d - d.mean(0)
    _, s, vt = np.linalg.svd(xc, full_matrices=False)
    np.testing.assert_allclose(mu.eigenvalues, s**2 / (len(d) - 1), rtol=1e-8, atol=1e-12)
    # Same subspace and the same vectors up to sign.
    np.testing.assert_allclose(np.abs(np.sum(mu.units * vt[:5], axis=1)), 1.0, atol=1e-8)
    np.testing.assert_allclose(mu.units @ mu.units.T, np.eye(5), atol=1e-10)


def test_variance_rule_and_reconstruction() -> None:
    d = _data()
    mu = fit_motion_units(d, min_variance=0.97)
    cum = mu.explained()
    assert cum[mu.n_units - 1] >= 0.97 and (mu.n_units == 1 or cum[mu.n_units - 2] < 0.97)
    err = d - mu.reconstruct(mu.project(d))
    # What PCA leaves out is exactly the variance of the dropped eigenvalues.
    np.testing.assert_allclose((err**2).sum() / (len(d) - 1), mu.eigenvalues[mu.n_units :].sum(), rtol=1e-8)
    np.testing.assert_allclose(mu.project(d).mean(0), 0.0, atol=1e-10)


def test_refit_is_deterministic_in_sign() -> None:
    d = _data()
    a, b = fit_motion_units(d, n_units=4), fit_motion_units(d[::-1].copy(), n_units=4)
    np.testing.assert_allclose(a.units, b.units, atol=1e-8)


def test_expression_units_eq1_eq2() -> None:
    rng = np.random.default_rng(1)
    d0 = _data(seed=2)
    mu = fit_motion_units(d0, n_units=5)
    smile = rng.standard_normal(30)
    smile -= mu.units.T @ (mu.units @ smile)  # a direction the utterance units cannot represent
    d1 = d0[:200] + np.outer(1 + 0.2 * rng.standard_normal(200), smile)
    ex = fit_expression_units(mu, d1, name="smile", n_units=2)
    # eq. 1: the residuals are orthogonal to the utterance units.
    r = mu.residual(d1)
    np.testing.assert_allclose(r @ mu.units.T, 0.0, atol=1e-9)
    np.testing.assert_allclose(ex.basis.mean, r.mean(0), atol=1e-12)
    # eq. 2 reconstructs the training frames with the analysed parameters (rank-1 residual + noise).
    c0, ck = analyse(mu, ex, d1)
    rec = compose(mu, c0, ex, ck)
    assert np.sqrt(((rec - d1) ** 2).mean()) < 0.02
    # Intensity scales only the expression part.
    half = compose(mu, c0, ex, ck, alpha=0.5)
    np.testing.assert_allclose(half, mu.reconstruct(c0) + 0.5 * ex.basis.reconstruct(ck))


def test_keyframe_conversion_matches_lstsq_and_round_trips() -> None:
    rng = np.random.default_rng(3)
    d = _data(seed=4)
    mu = fit_motion_units(d, n_units=5)
    k = rng.standard_normal((30, 8))
    keys = KeyframeSet(names=tuple(f"k{i}" for i in range(8)), shapes=k)
    umup = mu.project(d)
    b = mups_to_keyframes(keys, mu, umup)
    ref = np.linalg.lstsq(k, mu.reconstruct(umup).T, rcond=None)[0].T
    np.testing.assert_allclose(b, ref, atol=1e-9)
    c_back, _ = keyframes_to_mups(keys, mu, b)
    np.testing.assert_allclose(c_back, mu.project(ref @ k.T), atol=1e-9)
    # Keyframes that span the MU space (here: built from the units themselves) round-trip exactly.
    span = KeyframeSet(
        names=tuple(f"u{i}" for i in range(6)),
        shapes=np.column_stack([mu.mean, *mu.units]) @ rng.standard_normal((6, 6)),
    )
    assert round_trip_error(span, mu, umup).max() < 1e-9


def test_keyframes_in_the_mu_subspace() -> None:
    """Keyframes with a part outside the MUs (random columns) lose MUP information in landmark space; in
    the MU subspace eq. 4 solves the MUPs themselves: exact when the projections span the MUs, and the
    same as least squares of the MUPs on M_0^T K (independent computation)."""
    rng = np.random.default_rng(8)
    d = _data(seed=9)
    mu = fit_motion_units(d, n_units=5)
    umup = mu.project(d)
    keys = KeyframeSet(names=tuple(f"k{i}" for i in range(6)), shapes=rng.standard_normal((30, 6)))
    proj = in_mu_space(keys, mu)
    assert proj.names == keys.names
    np.testing.assert_allclose(mu.units @ proj.shapes, mu.units @ keys.shapes, atol=1e-12)
    assert round_trip_error(keys, mu, umup).max() > 0.05
    assert proj.ridge == 1e-6  # 6 keyframes in 5 MUs: dependent, a tiny ridge
    assert round_trip_error(proj, mu, umup).max() < 1e-4
    b = mups_to_keyframes(proj, mu, umup)
    target = umup + mu.units @ mu.mean  # M_0^T d for d = m_00 + M_0 c
    ref = np.linalg.lstsq(mu.units @ keys.shapes, target.T, rcond=None)[0].T  # the minimum-norm solution
    np.testing.assert_allclose(b, ref, atol=1e-3 * np.abs(ref).max())
    five = KeyframeSet(names=keys.names[:5], shapes=keys.shapes[:, :5])
    assert round_trip_error(in_mu_space(five, mu), mu, umup).max() < 1e-9  # as many as MUs: exact
    # With b >= 0 the frames outside the keyframes' cone cannot come back: the error is measured, not 0.
    nn = round_trip_error(proj, mu, umup, nonnegative=True)
    assert (nn >= 0).all() and nn.max() > 1e-3
    assert (mups_to_keyframes(proj, mu, umup[:20], nonnegative=True) >= 0).all()


def test_nonnegative_and_ridge_against_lstsq() -> None:
    rng = np.random.default_rng(5)
    k = np.abs(rng.standard_normal((20, 6)))
    keys = KeyframeSet(names=tuple("abcdef"), shapes=k, ridge=0.1)
    d = rng.standard_normal((5, 20))
    lam = 0.1 * (k**2).sum(0).mean()
    aug = np.vstack([k, np.sqrt(lam) * np.eye(6)])
    np.testing.assert_allclose(keys.ridge_rows(), aug, rtol=1e-15)  # the one ridge system (training.fit_maps's too)
    ref = np.linalg.lstsq(aug, np.hstack([d, np.zeros((5, 6))]).T, rcond=None)[0].T
    np.testing.assert_allclose(keys.weights(d), ref, atol=1e-9)
    nn = keys.weights(d, nonnegative=True)
    assert (nn >= 0).all()
    # The NNLS optimum is no worse than the clipped unconstrained solution.
    cost = lambda b: ((aug @ b.T - np.hstack([d, np.zeros((5, 6))]).T) ** 2).sum(0)
    assert (cost(nn) <= cost(np.clip(ref, 0, None)) + 1e-12).all()


def test_bad_input() -> None:
    with pytest.raises(InvalidFeaturesError, match="NaN"):
        fit_motion_units(np.array([[0.0, np.nan], [1.0, 2.0]]))
    with pytest.raises(InvalidFeaturesError, match=r"\(N >= 2"):
        fit_motion_units(np.zeros((1, 3)))
    mu = fit_motion_units(_data(), n_units=3)
    with pytest.raises(InvalidFeaturesError, match=r"\(\.\.\., 30\)"):
        mu.project(np.zeros((4, 29)))
    with pytest.raises(ConfigError, match="linearly dependent"):
        KeyframeSet(names=("a", "b"), shapes=np.ones((30, 2)))
    with pytest.raises(ConfigError, match="identifier"):
        fit_expression_units(mu, _data(), name="big smile")
