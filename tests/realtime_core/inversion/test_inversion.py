"""HMM inversion: eq. 7 as printed, the Gaussian conditional mean, batch EM, streaming."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import InvalidFeaturesError, StreamStateError
from realtime_core.hmm import AvHmm
from realtime_core.hmm.sampling import random_av_hmm, sample
from realtime_core.inversion import (
    ConditionalForm,
    HmmiConfig,
    StreamConfig,
    StreamingInverter,
    audio_posterior_estimate,
    hmm_inversion,
)
from realtime_core.metrics import acc
from tests.chunking import assert_chunk_invariant

DA, DV = 7, 3


@pytest.fixture(scope="module")
def model():
    return random_av_hmm(np.random.default_rng(11), n_states=4, n_mix=3, n_audio=DA, n_visual=DV)


@pytest.fixture(scope="module")
def data(model):
    return sample(model, np.random.default_rng(12), 240)[0]


def test_eq7_as_printed_equals_the_fast_form(model, data):
    """Eq. 7 evaluated literally with the blocks of an explicitly inverted Sigma_jk and
    arbitrary posteriors equals ConditionalForm.combine (Phi_v-weighted conditional means)."""
    form = ConditionalForm.from_model(model)
    rng = np.random.default_rng(0)
    oa = data[:20, :DA]
    post = rng.dirichlet(np.ones(model.n_states * model.n_mix), size=len(oa))
    _, cond = form.audio_terms(oa)
    fast = form.combine(post, cond)
    mus = model.means.reshape(-1, DA + DV)
    inv = np.linalg.inv(model.covars.reshape(-1, DA + DV, DA + DV))
    for t in range(len(oa)):
        lhs = np.zeros((DV, DV))
        rhs = np.zeros(DV)
        for c in range(len(mus)):
            phi_v, phi_va, phi_av = inv[c, DA:, DA:], inv[c, DA:, :DA], inv[c, :DA, DA:]
            da = oa[t] - mus[c, :DA]
            bracket = phi_v @ mus[c, DA:] - 0.5 * phi_va @ da - 0.5 * (da @ phi_av)
            lhs += post[t, c] * phi_v
            rhs += post[t, c] * bracket
        np.testing.assert_allclose(fast[t], np.linalg.solve(lhs, rhs), rtol=1e-9, atol=1e-9)


def test_single_component_gives_the_gaussian_conditional_mean(model, data):
    one = AvHmm(
        startprob=[1.0],
        transmat=[[1.0]],
        weights=[[1.0]],
        means=model.means[:1, :1],
        covars=model.covars[:1, :1],
        n_audio=DA,
    )
    mu, S = one.means[0, 0], one.covars[0, 0]
    oa = data[:, :DA]
    expect = mu[DA:] + (S[DA:, :DA] @ np.linalg.solve(S[:DA, :DA], (oa - mu[:DA]).T)).T
    form = ConditionalForm.from_model(one)
    np.testing.assert_allclose(audio_posterior_estimate(form, oa), expect, atol=1e-10)
    np.testing.assert_allclose(hmm_inversion(form, oa).visual, expect, atol=1e-10)


@pytest.mark.parametrize("init", ["audio-posterior", "random"])
def test_batch_hmmi_never_lowers_the_joint_likelihood(model, data, init):
    form = ConditionalForm.from_model(model)
    res = hmm_inversion(form, data[:, :DA], config=HmmiConfig(init=init, tol=0, max_iter=15))
    assert np.all(np.diff(res.history) >= -1e-9)
    if init == "random":
        assert res.history[-1] > res.history[0]
    else:
        assert acc(data[:, DA:], res.visual) > 0.5


def test_audio_posterior_start_avoids_the_random_start_local_optimum(model, data):
    """Why the default differs from the paper: from a random visual sequence EM settles
    in a poorer optimum (lower joint likelihood and accuracy) on this ambiguous audio."""
    form = ConditionalForm.from_model(model)
    ap = hmm_inversion(form, data[:, :DA])
    rnd = hmm_inversion(form, data[:, :DA], config=HmmiConfig(init="random", seed=1))
    assert ap.history[-1] > rnd.history[-1]
    assert acc(data[:, DA:], ap.visual) > acc(data[:, DA:], rnd.visual) + 0.1


KERNELS = pytest.mark.parametrize("kernel", ["numba", "numpy"])


@KERNELS
def test_streaming_with_a_large_lag_equals_the_batch_audio_posterior_estimate(model, data, kernel):
    form = ConditionalForm.from_model(model)
    st = StreamingInverter(form, config=StreamConfig(lag=10_000, dtype="float64", kernel=kernel))
    out = np.concatenate([st.push(data[:, :DA]), st.flush()])
    np.testing.assert_allclose(out, audio_posterior_estimate(form, data[:, :DA]), atol=1e-10)


@KERNELS
def test_streaming_lag_zero_equals_batch_filtering(model, data, kernel):
    form = ConditionalForm.from_model(model)
    st = StreamingInverter(form, config=StreamConfig(lag=0, dtype="float64", kernel=kernel))
    first = st.push(data[:1, :DA])
    assert first.shape == (1, DV)  # lag 0: every row comes out at once
    out = np.concatenate([first, st.push(data[1:, :DA]), st.flush()])
    np.testing.assert_allclose(out, audio_posterior_estimate(form, data[:, :DA], smoothing="forward"), atol=1e-10)


@KERNELS
@pytest.mark.parametrize("lag", [0, 3])
def test_streaming_same_output_for_any_chunking_and_float32_close(model, data, lag, kernel):
    form = ConditionalForm.from_model(model)
    oa = data[:, :DA]

    def make(dtype="float64"):
        return lambda: StreamingInverter(form, config=StreamConfig(lag=lag, dtype=dtype, kernel=kernel))

    whole = assert_chunk_invariant(make(), oa, atol=1e-12)
    # float32 matrix-vector product: same estimate to a small fraction of the visual spread.
    f32 = assert_chunk_invariant(make("float32"), oa, atol=1e-6, max_examples=5)
    assert np.abs(f32 - whole).max() < 1e-3 * data[:, DA:].std()


def test_lag_delays_output_by_lag_frames(model, data):
    st = StreamingInverter(ConditionalForm.from_model(model), config=StreamConfig(lag=3))
    counts = [len(st.push(data[i : i + 1, :DA])) for i in range(6)]
    assert counts == [0, 0, 0, 1, 1, 1]
    assert len(st.flush()) == 3


def test_bad_input(model):
    form = ConditionalForm.from_model(model)
    st = StreamingInverter(form)
    with pytest.raises(InvalidFeaturesError, match=r"\(k, 7\)"):
        st.push(np.zeros((2, 5)))
    with pytest.raises(InvalidFeaturesError, match="NaN"):
        st.push(np.full((1, DA), np.nan))
    st.flush()
    with pytest.raises(StreamStateError):
        st.push(np.zeros((1, DA)))
    with pytest.raises(InvalidFeaturesError):
        audio_posterior_estimate(form, np.zeros((4, 3)))
