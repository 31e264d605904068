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
    apart = np.array([0.1, 0.1])  # the fit keeps the lips 0.006-0.007 apart, no wider than the source's 0.009
    fit = rest + gap @ (free.weights(apart) @ kf)
    assert fit.min() > 0 and fit.max() < (rest + gap @ (apart @ a)).min()
    assert km.weights(apart).tobytes() == free.weights(apart).tobytes()
    # A source that itself crosses by 0.006 (rest 0.01, raised 0.016): the fit may cross as far, no further.
    x = np.array([2.0, 0.0])
    floor = min(0.0, float((rest + gap @ (x @ a)).min()))
    w = km.weights(x)
    assert floor < 0 and (rest + gap @ (w @ kf)).min() >= floor - 1e-5


def test_the_lip_contact_holds_closed_lips_at_the_source_gap_and_leaves_open_frames_bit_identical():
    # An OVR head at /m/: the reference motion keeps the lips closed (gap 0.005) while moving elsewhere, and
    # the only keyframe with that motion also opens the lips by 0.05 (the least-squares fit took it).
    from scipy.optimize import minimize

    from realtime_core.face.keyframes import LIP_CLOSED_GAP, LIP_OPEN_TOL

    a = np.array([[-0.005, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0], [0.0, -0.1, 0.0, 0.0]])  # press, other, open
    kf = np.array([[0.05, 0.0, 1.0, 0.0], [0.0, 0.0, 0.3, 1.0], [-0.01, 0.0, 0.0, 0.5], [0.0, -0.1, 0.0, 0.0]])
    rest, gap = np.array([0.01]), np.array([[1.0, -1.0, 0.0, 0.0]])  # upper y minus lower y
    free = KeyframeMap.from_reference(kf, a)
    km = KeyframeMap.from_reference(kf, a, contact=(rest, gap))
    x = np.array([1.0, 0.2, 0.0])
    src = float(rest[0] + gap[0] @ (x @ a))
    assert src == pytest.approx(0.005) and src < LIP_CLOSED_GAP
    assert rest[0] + gap[0] @ (free.weights(x) @ kf) > src + 0.03  # the unconstrained fit opens the lips
    obj = lambda b: 0.5 * b @ km.gram @ b - b @ (km.cross @ x)
    cons = [
        {"type": "ineq", "fun": lambda b: rest + gap @ (b @ kf)},
        {"type": "ineq", "fun": lambda b: src + LIP_OPEN_TOL - (rest + gap @ (b @ kf))},
    ]
    ref = minimize(obj, np.zeros(4), bounds=[(0, 1)] * 4, constraints=cons, method="SLSQP", tol=1e-14).x
    ws = {kernel: km.weights(x, kernel=kernel) for kernel in ("numba", "numpy")}
    np.testing.assert_allclose(ws["numba"], ws["numpy"], rtol=0, atol=1e-10)
    for w in ws.values():
        g = float(rest[0] + gap[0] @ (w @ kf))
        assert src <= g <= src + LIP_OPEN_TOL + 1e-5  # held at the source's gap (plus the tolerance)
        assert obj(w) <= obj(ref) + 1e-3 * abs(obj(ref))
        np.testing.assert_allclose(w, ref, atol=2e-3)
    # Open frames (the source parts the lips 0.1: the ceiling lets go) are the unconstrained solve, bit for
    # bit, also where the fit opens them further than the source (0.05 past it here).
    for x_open in (np.array([1.0, 0.2, 1.0]), np.array([0.0, 0.5, 0.6]), np.array([0.3, 0.0, 0.9])):
        assert rest[0] + gap[0] @ (x_open @ a) > LIP_CLOSED_GAP + 0.03
        for kernel in ("numba", "numpy"):
            assert km.weights(x_open, kernel=kernel).tobytes() == free.weights(x_open, kernel=kernel).tobytes()
    fit_open = rest[0] + gap[0] @ (free.weights(np.array([1.0, 0.2, 1.0])) @ kf)
    assert fit_open > rest[0] + gap[0] @ (np.array([1.0, 0.2, 1.0]) @ a) + 0.03


def test_the_compiled_morph_product_equals_numpy_and_gives_each_frame_the_same_bits_at_any_batch():
    # A server computes a loop turn's vertex frames in one pass (MorphRig.displacements_rows): a frame's
    # row must not depend on which other frames shared its batch. Shapes off the kernel's steps: 19
    # targets (4 + 4 + 4 + 4 + 3), columns spanning three blocks and a partial one.
    from realtime_core.face.compiled import MORPH_BLOCK, morph_displacements

    rng = np.random.default_rng(12)
    n = 3 * MORPH_BLOCK + 77
    rows = (rng.normal(size=(19, n)) * 1e-3).astype(np.float32)
    w = rng.uniform(0, 1, size=(11, 19)).astype(np.float32)
    w[3] = 0.0  # silence: exactly zero
    whole = morph_displacements(w, rows, np.empty((11, n), dtype=np.float32))
    ref = np.stack([np.dot(x.astype(np.float64), rows.astype(np.float64)) for x in w])  # float64 product
    peak = np.abs(ref).max()
    np.testing.assert_allclose(whole, ref, rtol=0, atol=4e-7 * peak)  # float32 rounding of 19 terms
    assert not whole[3].any()
    for b in (1, 2, 5):  # batches of other sizes, in another order
        for i0 in range(0, 11, b):
            idx = np.arange(i0, min(i0 + b, 11))[::-1]
            part = morph_displacements(np.ascontiguousarray(w[idx]), rows, np.empty((len(idx), n), dtype=np.float32))
            assert part.tobytes() == whole[idx].tobytes()


def test_morph_rig_rows_compiled_equal_the_numpy_reference(builtin_head):
    from assets.heads.head import builtin_morph_head
    from realtime_core.face.keyframes import MorphRig

    rig = builtin_morph_head().rig  # the head facecast serve animates by default
    assert isinstance(rig, MorphRig)
    rng = np.random.default_rng(13)
    params = rng.normal(0.0, 0.05, (6, 4))
    params[:, 2] = np.abs(params[:, 2])
    w = np.stack([rig.weights(p) for p in params])
    fast, ref = rig.displacements_rows(w), rig.displacements_rows(w, kernel="numpy")
    assert fast.shape == ref.shape == (6, 3 * len(rig.moving)) and fast.dtype == np.float32
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-6 * np.abs(ref).max())
    for p, row in zip(params, ref):  # the reference is the one-frame displacements
        assert rig.displacements(p).reshape(-1).tobytes() == row.tobytes()
    with pytest.raises(ConfigError, match="weights must be"):
        rig.displacements_rows(w[:, :5])
    with pytest.raises(ConfigError, match="kernel"):
        rig.displacements_rows(w, kernel="gpu")
