"""training.fit_maps's signed-unit fit solves KeyframeSet's own ridge problem (it once recomputed the ridge's
scaling itself): with the lip-gap rows empty of information, its lip-gap directions give exactly the set's
non-negative weights."""

from __future__ import annotations

import numpy as np

from realtime_core.motion_units import KeyframeSet
from training.fit_maps import LIP_GAP_DIRECTIONS, UNIT_IOD, _signed_fit


def test_the_lip_gap_directions_solve_the_sets_own_ridge_problem() -> None:
    rng = np.random.default_rng(3)
    # (30, 6) non-negative keyframes, a large ridge (a scaling of its own would move the weights by ~10 %).
    keys = KeyframeSet(names=tuple("abcdef"), shapes=np.abs(rng.standard_normal((30, 6))), ridge=0.5)
    # (D, 4): the rig's displacement per IOD of each parameter, each lip-gap direction near the keyframes' cone.
    motion = rng.standard_normal((30, 4))
    for i, sign in LIP_GAP_DIRECTIONS:
        motion[:, i] = sign * (keys.shapes @ np.abs(rng.standard_normal(6)) + 0.1 * motion[:, i])

    def shape_of(p: np.ndarray) -> np.ndarray:
        return motion @ p

    gaps = np.zeros((3, 6))  # lip-gap rows that add nothing to the least squares
    pos, neg = _signed_fit(keys, shape_of, gaps, lambda d: np.zeros(3))
    for i, sign in LIP_GAP_DIRECTIONS:
        e = np.zeros(4)
        e[i] = sign * UNIT_IOD
        want = keys.weights(shape_of(e), nonnegative=True) / UNIT_IOD
        got = (pos if sign > 0 else neg)[:, i]
        assert want.max() > 0  # a direction the keyframes reach: the comparison is not of two zero vectors
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
