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
