"""Forward-backward, expected transitions and Viterbi against brute-force enumeration."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from realtime_core import InvalidFeaturesError
from realtime_core.hmm import expected_transitions, forward_backward, viterbi


@pytest.fixture
def tiny():
    rng = np.random.default_rng(0)
    n, T = 3, 6
    start = rng.dirichlet(np.ones(n))
    trans = rng.dirichlet(np.ones(n), size=n)
    trans[0, 2] = 0.0  # an impossible transition must stay impossible
    trans /= trans.sum(axis=1, keepdims=True)
    log_b = rng.standard_normal((T, n)) * 3
    return start, trans, log_b


def _enumerate(start, trans, log_b):
    T, n = log_b.shape
    joint = {}
    for path in itertools.product(range(n), repeat=T):
        p = start[path[0]] * np.exp(log_b[0, path[0]])
        for t in range(1, T):
            p *= trans[path[t - 1], path[t]] * np.exp(log_b[t, path[t]])
        joint[path] = p
    return joint


def test_forward_backward_equals_enumeration(tiny):
    start, trans, log_b = tiny
    T, n = log_b.shape
    joint = _enumerate(start, trans, log_b)
    total = sum(joint.values())
    gamma_ref = np.zeros((T, n))
    xi_ref = np.zeros((n, n))
    for path, p in joint.items():
        for t in range(T):
            gamma_ref[t, path[t]] += p / total
        for t in range(T - 1):
            xi_ref[path[t], path[t + 1]] += p / total
    with np.errstate(divide="ignore"):
        ls, lt = np.log(start), np.log(trans)
    gamma, loglik, la, lb = forward_backward(ls, lt, log_b)
    assert loglik == pytest.approx(np.log(total), rel=1e-12)
    np.testing.assert_allclose(gamma, gamma_ref, atol=1e-12)
    xi = expected_transitions(la, lb, lt, log_b, loglik)
    np.testing.assert_allclose(xi, xi_ref, atol=1e-12)
    assert xi[0, 2] == 0.0


def test_viterbi_equals_enumeration(tiny):
    start, trans, log_b = tiny
    joint = _enumerate(start, trans, log_b)
    best = max(joint, key=joint.get)
    with np.errstate(divide="ignore"):
        path, logp = viterbi(np.log(start), np.log(trans), log_b)
    assert tuple(path) == best
    assert logp == pytest.approx(np.log(joint[best]), rel=1e-12)


def test_long_sequences_do_not_underflow():
    rng = np.random.default_rng(1)
    n = 4
    log_b = rng.standard_normal((20000, n)) * 50 - 400  # likelihoods far below float range
    gamma, loglik, _, _ = forward_backward(np.log(np.full(n, 0.25)), np.log(np.full((n, n), 0.25)), log_b)
    assert np.isfinite(loglik) and np.allclose(gamma.sum(axis=1), 1.0)


def test_shape_errors():
    with pytest.raises(InvalidFeaturesError, match="shape mismatch"):
        forward_backward(np.zeros(3), np.zeros((3, 3)), np.zeros((5, 4)))
    with pytest.raises(InvalidFeaturesError, match="empty"):
        forward_backward(np.zeros(3), np.zeros((3, 3)), np.zeros((0, 3)))
