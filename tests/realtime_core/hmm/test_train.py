"""Baum-Welch: monotone objective, priors keep covariances PD, recovery of a known
audio-visual HMM, and a cross-check of the likelihood trajectory with hmmlearn."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import InvalidFeaturesError, ModelFormatError
from realtime_core.hmm import AvHmm, TrainConfig, baum_welch, fit, init_model, log_likelihood
from realtime_core.hmm.sampling import random_av_hmm, sample
from realtime_core.inversion import ConditionalForm, audio_posterior_estimate
from realtime_core.metrics import acc, amse
from tests.prerequisites import require_module


def assert_objective_non_decreasing(history, tol=1e-9):
    """Like hmmlearn's assert_log_likelihood_increasing: EM may never go down."""
    diffs = np.diff(history)
    assert np.all(diffs >= -tol), f"EM objective fell: {diffs.min():.3g} in {np.round(history, 6)}"


@pytest.mark.slow
@pytest.mark.parametrize("cov", ["full", "diag"])
def test_em_objective_never_decreases(cov):
    rng = np.random.default_rng(0)
    true = random_av_hmm(rng, n_states=3, n_mix=2, n_audio=5, n_visual=2)
    seqs = [sample(true, rng, 150)[0] for _ in range(6)]
    res = fit(seqs, n_audio=5, config=TrainConfig(n_states=3, n_mix=2, covariance_type=cov, n_iter=15, tol=0))
    assert len(res.history) == 16
    assert_objective_non_decreasing(res.history)
    assert res.history[-1] > res.history[0] + 0.05  # and it actually learned something


@pytest.mark.slow
def test_prior_keeps_every_covariance_positive_definite_with_fewer_frames_than_dims():
    """81-dim full covariances from 60 frames: without a prior each component's scatter
    has rank < 81; with it every covariance stays PD (AvHmm validates by Cholesky)."""
    rng = np.random.default_rng(1)
    x = rng.standard_normal((60, 81))
    cfg = TrainConfig(n_states=3, n_mix=2, n_iter=5, tol=0)
    res = fit([x[:30], x[30:]], n_audio=77, config=cfg)
    assert_objective_non_decreasing(res.history)
    eig = np.linalg.eigvalsh(res.model.covars)
    assert eig.min() > 0
    # The prior is what does it: with no prior the M-step has a singular covariance.
    with pytest.raises(ModelFormatError, match="not positive definite"):
        baum_welch(
            [x[:30], x[30:]],
            res.model,
            config=TrainConfig(n_states=3, n_mix=2, n_iter=1, tol=0, covar_prior_weight=0.0),
        )


@pytest.mark.slow
def test_training_recovers_a_known_audio_visual_hmm():
    """Data sampled from a known AV-HMM (N=6, M=2, 77 audio + 4 visual dims, 24k frames).
    The trained model's held-out inversion accuracy (audio-posterior estimate) must come
    within 0.05 of the true model's rho and 0.08 of its eps, and its held-out
    log-likelihood per frame within 1.5 nats of the true model's (81 dims)."""
    rng = np.random.default_rng(7)
    da, dv = 77, 4
    true = random_av_hmm(rng, n_states=6, n_mix=2, n_audio=da, n_visual=dv)
    train = [sample(true, rng, 400)[0] for _ in range(60)]
    test = [sample(true, rng, 400)[0] for _ in range(5)]
    res = fit(train, n_audio=da, config=TrainConfig(n_states=6, n_mix=2, n_iter=25, tol=1e-4, seed=0))
    assert_objective_non_decreasing(res.history)

    def scores(model):
        form = ConditionalForm.from_model(model)
        est = np.concatenate([audio_posterior_estimate(form, s[:, :da]) for s in test])
        truth = np.concatenate([s[:, da:] for s in test])
        return acc(truth, est), amse(truth, est)

    rho_true, eps_true = scores(true)
    rho, eps = scores(res.model)
    assert rho_true > 0.5  # the generator makes audio informative about the visual part
    assert rho > rho_true - 0.05, (rho, rho_true)
    assert eps < eps_true + 0.08, (eps, eps_true)
    n = sum(len(s) for s in test)
    assert log_likelihood(res.model, test) / n > log_likelihood(true, test) / n - 1.5


@pytest.mark.slow
def test_same_trajectory_as_hmmlearn_from_the_same_initial_model():
    """hmmlearn's GMMHMM re-estimates full covariances around the previous means;
    with centering="previous" and no priors, our EM takes the same steps."""
    hmm = require_module("hmmlearn.hmm")
    rng = np.random.default_rng(3)
    true = random_av_hmm(rng, n_states=3, n_mix=2, n_audio=3, n_visual=2)
    seqs = [sample(true, rng, 200)[0] for _ in range(5)]
    cfg = TrainConfig(
        n_states=3,
        n_mix=2,
        n_iter=8,
        tol=0,
        covar_prior_weight=0.0,
        pseudo_count=0.0,
        centering="previous",
        resp_floor=0.0,
    )
    init = init_model(seqs, n_audio=3, config=cfg)
    ours = baum_welch(seqs, init, config=cfg).history

    ref = hmm.GMMHMM(
        n_components=3,
        n_mix=2,
        covariance_type="full",
        n_iter=1,
        tol=0,
        init_params="",
        params="stmcw",
        implementation="log",
    )
    ref.startprob_, ref.transmat_ = init.startprob.copy(), init.transmat.copy()
    ref.weights_, ref.means_, ref.covars_ = init.weights.copy(), init.means.copy(), init.covars.copy()
    x, lengths = np.concatenate(seqs), [len(s) for s in seqs]
    theirs = []
    for _ in range(8):
        ref.fit(x, lengths)  # one E-step (records log P at the current model) + one M-step
        theirs.append(ref.monitor_.history[-1] / len(x))
    np.testing.assert_allclose(ours[:8], theirs, rtol=1e-9, atol=1e-9)


def test_bad_training_input():
    with pytest.raises(InvalidFeaturesError, match="no training sequences"):
        fit([], n_audio=2, config=TrainConfig(n_states=2, n_mix=1))
    with pytest.raises(InvalidFeaturesError, match="NaN"):
        fit([np.full((50, 4), np.nan)], n_audio=2, config=TrainConfig(n_states=2, n_mix=1))
    with pytest.raises(InvalidFeaturesError, match="too few"):
        fit([np.zeros((3, 4))], n_audio=2, config=TrainConfig(n_states=2, n_mix=2))


def test_model_validation_names_the_problem():
    rng = np.random.default_rng(0)
    good = random_av_hmm(rng, n_states=2, n_mix=1, n_audio=3, n_visual=1)
    bad = good.covars.copy()
    bad[1, 0] = -np.eye(4)
    from realtime_core import ModelFormatError

    with pytest.raises(ModelFormatError, match="state 1, mixture 0 is not positive definite"):
        AvHmm(
            startprob=good.startprob,
            transmat=good.transmat,
            weights=good.weights,
            means=good.means,
            covars=bad,
            n_audio=3,
        )
    with pytest.raises(ModelFormatError, match="transmat must have shape"):
        AvHmm(
            startprob=good.startprob,
            transmat=np.eye(3),
            weights=good.weights,
            means=good.means,
            covars=good.covars,
            n_audio=3,
        )
