"""The compiled bounded keyframe solve (realtime_core.face.compiled) against the numpy reference."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from realtime_core import ConfigError
from realtime_core.face.keyframes import KeyframeMap


def test_compiled_box_qp_equals_the_numpy_reference_and_scipy_bvls():
    rng = np.random.default_rng(8)
    kf = rng.normal(size=(30, 120))
    kf[5] = kf[4] + 1e-3 * rng.normal(size=120)  # a near duplicate, as target sets often have
    km = KeyframeMap.from_reference(kf, rng.normal(size=(6, 120)))
    chol = np.linalg.cholesky(km.gram)
    xs = rng.normal(size=(60, 6)) * 2
    fast = km.weights(xs)
    ref = km.weights(xs, kernel="numpy")
    assert 0.1 < np.mean((ref <= 0) | (ref >= 1)) < 0.9  # the bounds are active: the active set matters
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-10)
    for x, w in zip(xs[:10], fast):  # and both are the bounded least-squares solution
        f = km.cross @ x
        bvls = lsq_linear(chol.T, np.linalg.solve(chol, f), bounds=(0, 1), method="bvls").x
        np.testing.assert_allclose(w, bvls, atol=1e-6)


def test_one_frame_equals_its_row_of_a_batch_bit_for_bit():
    # A live vertex viewer solves one frame at a time (the kernel called directly); a batch goes
    # through the per-row loop. The same frame must give the same bytes either way.
    rng = np.random.default_rng(9)
    km = KeyframeMap.from_reference(rng.normal(size=(19, 90)), rng.normal(size=(52, 90)))
    xs = np.abs(rng.normal(size=(40, 52)))
    batch = km.weights(xs)
    for x, row in zip(xs, batch):
        one = km.weights(x)
        assert one.shape == (19,) and one.dtype == np.float64
        assert one.tobytes() == row.tobytes()
    strided = np.stack([xs[0], -xs[0]], axis=1)[:, 0]  # a non-contiguous (52,) view of xs[0]
    assert not strided.flags.c_contiguous
    assert km.weights(strided).tobytes() == batch[0].tobytes()


def test_unknown_kernel_is_refused():
    km = KeyframeMap.from_reference(np.eye(3), np.eye(3))
    with pytest.raises(ConfigError, match="kernel"):
        km.weights(np.ones(3), kernel="gpu")


def _lip_problem():
    """Two lip columns (reference dims 0-3: upper y, lower y per column) and two other dims. The source
    raises the lower lip 0.008 (rest gaps 0.01: still apart) with a motion elsewhere that only keyframe 0
    (a "press", raising the lower lip 0.05) reproduces: the unconstrained fit crosses the lips."""
    a = np.array([[0.0, 0.008, 0.0, 0.008, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])
    kf = np.array([[0.0, 0.05, 0.0, 0.05, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.3, 1.0], [0.0, -0.02, 0.0, 0.0, 0.0, 0.5]])
    rest = np.array([0.01, 0.01])
    gap = np.array([[1.0, -1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, -1.0, 0.0, 0.0]])
    return kf, a, rest, gap


def test_the_lip_contact_keeps_a_crossing_fit_apart_at_the_constrained_least_squares_solution():
    from scipy.optimize import minimize

    kf, a, rest, gap = _lip_problem()
    free = KeyframeMap.from_reference(kf, a)
    km = KeyframeMap.from_reference(kf, a, contact=(rest, gap))
    x = np.array([1.0, 0.2])
    before = rest + gap @ (free.weights(x) @ kf)
    assert before.min() < -0.02  # the fit without the contact crosses the lips (the bug)
    for kernel in ("numba", "numpy"):
        w = km.weights(x, kernel=kernel)
        g = rest + gap @ (w @ kf)
        assert g.min() >= -1e-5 and np.all((w >= 0) & (w <= 1))
        # The constrained QP solved independently (SLSQP): same objective value within tolerance.
        obj = lambda b: 0.5 * b @ km.gram @ b - b @ (km.cross @ x)
        cons = {"type": "ineq", "fun": lambda b: rest + gap @ (b @ kf)}
        ref = minimize(obj, np.zeros(3), bounds=[(0, 1)] * 3, constraints=[cons], method="SLSQP", tol=1e-14).x
        assert obj(w) <= obj(ref) + 1e-3 * abs(obj(ref))  # (the search stops within CONTACT_TOL of the floor)
        np.testing.assert_allclose(w, ref, atol=2e-3)


def test_the_lip_contact_changes_no_frame_that_keeps_the_lips_apart_or_that_the_source_crosses_itself():
    kf, a, rest, gap = _lip_problem()
    free = KeyframeMap.from_reference(kf, a)
    km = KeyframeMap.from_reference(kf, a, contact=(rest, gap))
    apart = np.array([0.1, 0.5])  # the fit raises the lower lip 0.005: apart
    assert (rest + gap @ (free.weights(apart) @ kf)).min() > 0
    assert km.weights(apart).tobytes() == free.weights(apart).tobytes()
    # A source that itself crosses by 0.006 (rest 0.01, raised 0.016): the fit may cross as far, no further.
    x = np.array([2.0, 0.0])
    floor = min(0.0, float((rest + gap @ (x @ a)).min()))
    w = km.weights(x)
    assert floor < 0 and (rest + gap @ (w @ kf)).min() >= floor - 1e-5
