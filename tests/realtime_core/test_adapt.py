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


@pytest.fixture(scope="module")
def shipped():
    """The shipped default model (it has a learned readout that takes the centred audio row) and 8 s of
    speech-like sound as an enrolment."""
    from assets.modelfile import load_model
    from tests.speech import speechlike

    return load_model(None), speechlike(8.0, 16000, seed=3) * 0.6


def test_an_infinite_relevance_gives_back_the_model_and_its_live_output_bit_for_bit(shipped) -> None:
    """MAP with an infinite prior weight is no adaptation: the same HMM arrays and the same live frames (it was
    inf * mu0 / inf = NaN, refused as 'weights contains NaN or inf')."""
    from realtime_core.adaptation import adapt_av_model
    from realtime_core.pipeline import speech_to_params

    model, enrol = shipped
    inf = float("inf")
    adapted, res = adapt_av_model(model, [enrol], config=AdaptConfig(relevance=inf, weight_relevance=inf))
    assert res.n_frames > 150 and np.all(np.isfinite(res.history))
    for name in ("means", "weights", "covars", "transmat", "startprob"):
        np.testing.assert_array_equal(getattr(adapted.hmm, name), getattr(model.hmm, name))
    speech = enrol[::-1].copy()  # other sounds of the same "voice"
    np.testing.assert_array_equal(speech_to_params(adapted, speech), speech_to_params(model, speech))


def test_adapting_leaves_the_readout_the_audio_rows_it_was_fitted_on(shipped) -> None:
    """The inverter centres each audio row at ``form.center``, a mean of the audio means and weights, which adaptation
    moves: the adapted model's readout must map the newly centred rows as the original readout maps the rows centred
    as it was fitted (it saw them shifted by up to 0.26 per feature with 48 s of GRID s1 before)."""
    from realtime_core.adaptation import adapt_av_model
    from realtime_core.inversion import StreamConfig

    model, enrol = shipped
    adapted, _ = adapt_av_model(model, [enrol])
    shift = adapted.form.center - model.form.center
    assert np.abs(shift).max() > 0.01  # the centre did move
    fe = adapted.front_end(kernel="numpy")
    oa = np.concatenate([fe.push(enrol), fe.flush()])
    raw, post, audio = adapted.inverter(StreamConfig(kernel="numpy", dtype="float64")).trace(oa)
    np.testing.assert_allclose(
        adapted.readout.apply(raw, post, audio), model.readout.apply(raw, post, audio + shift), atol=1e-9
    )
    assert not np.allclose(model.readout.apply(raw, post, audio), model.readout.apply(raw, post, audio + shift))
