"""MAP speaker adaptation of the audio side (realtime_core.hmm.adapt, realtime_core.adaptation)."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ConfigError, InvalidFeaturesError
from realtime_core.hmm import AvHmm
from realtime_core.hmm.adapt import AdaptConfig, audio_log_likelihood, map_adapt
from realtime_core.hmm.sampling import random_av_hmm, sample
from realtime_core.inversion import ConditionalForm


def _shifted(model: AvHmm, shift: np.ndarray) -> AvHmm:
    """The 'new speaker': the same model with every audio mean moved by ``shift (N, M, Da)``."""
    means = model.means.copy()
    means[:, :, : model.n_audio] += shift
    return AvHmm(
        startprob=model.startprob,
        transmat=model.transmat,
        weights=model.weights,
        means=means,
        covars=model.covars,
        n_audio=model.n_audio,
    )


@pytest.fixture(scope="module")
def setup():
    rng = np.random.default_rng(7)
    si = random_av_hmm(rng, n_states=4, n_mix=2, n_audio=3, n_visual=2)
    shift = 0.6 + 0.2 * rng.standard_normal((4, 2, 3))  # a voice: mostly one common offset
    truth = _shifted(si, shift)
    enrol = [sample(truth, rng, 150)[0][:, :3] for _ in range(6)]  # audio only: 900 frames
    held = [sample(truth, rng, 150)[0][:, :3] for _ in range(6)]
    return si, truth, enrol, held


def test_moves_means_towards_the_new_voice_and_fits_its_held_out_speech(setup) -> None:
    si, truth, enrol, held = setup
    res = map_adapt(si, enrol, config=AdaptConfig(relevance=8.0, n_iter=8))
    da = si.n_audio
    occ = res.occupancy.ravel()
    err = lambda m: np.linalg.norm((m.means[:, :, :da] - truth.means[:, :, :da]).reshape(-1, da), axis=1)
    before, after = err(si), err(res.model)
    visited = occ > 20
    assert visited.sum() >= 4
    assert np.all(after[visited] < 0.5 * before[visited])  # well-visited components: most of the way
    assert np.average(after, weights=occ) < 0.4 * np.average(before, weights=occ)
    ll_si = audio_log_likelihood(si, held) / 900
    ll_ad = audio_log_likelihood(res.model, held) / 900
    ll_truth = audio_log_likelihood(truth, held) / 900
    assert ll_ad > ll_si + 0.2 and ll_ad <= ll_truth + 0.05


def test_map_objective_never_decreases(setup) -> None:
    si, _, enrol, _ = setup
    for cfg in (
        AdaptConfig(relevance=2.0, n_iter=10, tol=0.0),
        AdaptConfig(relevance=30.0, weight_relevance=None, n_iter=10, tol=0.0),
    ):
        h = map_adapt(si, enrol[:2], config=cfg).history
        assert len(h) == 11 and np.all(np.diff(h) >= -1e-9), np.diff(h)
        assert h[-1] > h[0]


def test_zero_data_is_the_identity(setup) -> None:
    si, _, _, _ = setup
    for data in ([], [np.zeros((0, 3))]):
        res = map_adapt(si, data)
        assert res.model is si and res.n_frames == 0 and res.history == []


def test_visual_side_kept_and_regression_anchored_on_the_new_audio_mean(setup) -> None:
    si, _, enrol, _ = setup
    ad = map_adapt(si, enrol).model
    da = si.n_audio
    np.testing.assert_array_equal(ad.means[:, :, da:], si.means[:, :, da:])
    np.testing.assert_array_equal(ad.covars, si.covars)
    np.testing.assert_array_equal(ad.transmat, si.transmat)
    assert not np.allclose(ad.means[:, :, :da], si.means[:, :, :da])
    assert not np.allclose(ad.weights, si.weights) and np.allclose(ad.weights.sum(axis=1), 1.0)
    # m_c(o_a) = mu_v + R (o_a - mu_a): the new voice's mean frame of component c gives c's mouth
    form = ConditionalForm.from_model(ad)
    mu_a = ad.means.reshape(-1, ad.n_dim)[:, :da]
    _, cond = form.audio_terms(mu_a)  # (C frames, C components, Dv)
    c = np.arange(len(mu_a))
    np.testing.assert_allclose(cond[c, c], ad.means.reshape(-1, ad.n_dim)[:, da:], atol=1e-9)
    # and the regressions themselves are unchanged
    np.testing.assert_allclose(form.reg, ConditionalForm.from_model(si).reg, atol=1e-12)


def test_weights_fixed_without_weight_relevance(setup) -> None:
    si, _, enrol, _ = setup
    ad = map_adapt(si, enrol, config=AdaptConfig(weight_relevance=None)).model
    np.testing.assert_array_equal(ad.weights, si.weights)


def test_bad_input_is_named(setup) -> None:
    si, _, _, _ = setup
    with pytest.raises(InvalidFeaturesError, match=r"\(T, 3\)"):
        map_adapt(si, [np.zeros((10, 4))])
    with pytest.raises(InvalidFeaturesError, match="NaN"):
        map_adapt(si, [np.full((10, 3), np.nan)])
    with pytest.raises(ConfigError, match="relevance"):
        AdaptConfig(relevance=0)
