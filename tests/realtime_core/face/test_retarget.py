"""Projection, interpolation and rig invariants on small synthetic meshes (no files needed)."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ConfigError
from realtime_core.face.adaptation import adapt_displacements, affine_adaptation
from realtime_core.face.interpolation import InterpolationConfig, barycentric_2d, interpolation_weights
from realtime_core.face.projection import project
from realtime_core.face.rbf import gcv_scores, rbf_map


def grid(x0, x1, y0, y1, nx, ny, z=0.0):
    xs, ys = np.meshgrid(np.linspace(x0, x1, nx), np.linspace(y0, y1, ny))
    v = np.c_[xs.ravel(), ys.ravel(), np.full(xs.size, z)]
    t = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = j * nx + i
            t += [[a, a + 1, a + nx + 1], [a, a + nx + 1, a + nx]]
    return v, np.array(t)


def two_lips():
    """Upper and lower lip strips, 0.04 apart and not connected (a closed mouth with separate lips)."""
    vu, tu = grid(-1, 1, 0.02, 0.5, 21, 7)
    vl, tl = grid(-1, 1, -0.5, -0.02, 21, 7)
    v = np.vstack([vu, vl])
    t = np.vstack([tu, tl + len(vu)])
    upper = np.zeros(len(v), dtype=bool)
    upper[: len(vu)] = True
    return v, t, upper


@pytest.mark.parametrize("walk", ["shortest", "greedy"])
def test_geodesic_check_rejects_triangle_across_the_lips(walk):
    v, t, upper = two_lips()
    # A simple-model triangle on the upper lip whose third vertex was placed a little too low:
    # its closest head vertex is on the lower lip, 0.04 away across the mouth gap.
    simple = np.array([[-0.3, 0.12, 0.0], [0.3, 0.12, 0.0], [0.0, -0.005, 0.0]])
    tri = np.array([[0, 1, 2]])
    naive = project(simple, tri, v, t, geodesic_check=False)
    assert upper[naive.control[:2]].all() and not upper[naive.control[2]]
    checked = project(simple, tri, v, t, walk=walk)
    assert upper[checked.control].all(), "the check must move the stray vertex back to the upper lip"
    assert not checked.bad_triangles.any()
    assert checked.replacements >= 1
    assert len(set(checked.control.tolist())) == 3  # never two to one


def test_projection_is_one_to_one():
    v, t = grid(0, 1, 0, 1, 5, 5)
    s = np.repeat([[0.5, 0.5, 0.01]], 4, axis=0)  # four simple vertices on the same spot
    r = project(s, np.zeros((0, 3), int), v, t)
    assert len(set(r.control.tolist())) == 4


def test_interpolation_barycentric_and_fallback_eq10():
    v, _t = grid(0, 1, 0, 1, 11, 11)
    ctrl = np.array([0, 10, 110])  # corners (0,0), (1,0), (0,1)
    tri = np.array([[0, 1, 2]])
    beta = 0.5
    it = interpolation_weights(v, v[:, :2], ctrl, tri, config=InterpolationConfig(beta=beta))
    g = it.weights.toarray()
    inside = v[:, 0] + v[:, 1] <= 1 + 1e-9
    np.testing.assert_array_equal(it.inside | np.isin(np.arange(len(v)), ctrl), inside)
    # Eq. 8-9: barycentric weights reproduce the position (affine precision) and sum to one.
    np.testing.assert_allclose(g[inside] @ v[ctrl], v[inside], atol=1e-12)
    np.testing.assert_allclose(g[inside].sum(1), 1.0)
    # Eq. 10 by hand for the far corner (1, 1): distances to the three controls.
    k = 120
    d = np.linalg.norm(v[ctrl] - v[k], axis=1)
    dm = d.min()
    np.testing.assert_allclose(g[k], beta * np.exp(-((d - dm) ** 2) / dm**2), atol=1e-12)


def test_barycentric_2d():
    g = barycentric_2d(np.array([[0.25, 0.25]]), np.zeros(2), np.array([1.0, 0]), np.array([0, 1.0]))
    np.testing.assert_allclose(g, [[0.5, 0.25, 0.25]])


def test_rbf_gcv_matches_brute_force_and_interpolates_smooth_fields():
    rng = np.random.default_rng(0)
    c = rng.uniform(-1, 1, size=(30, 3))
    y = np.c_[np.sin(c[:, 0]), c[:, 1] ** 2]
    lams = np.logspace(-6, 0, 7)
    r2 = ((c - c.mean(0)) ** 2).sum(1).mean()
    h = np.exp(-((c[:, None] - c[None]) ** 2).sum(-1) / r2)
    brute = []
    for lam in lams:  # GCV from its definition with the explicit influence matrix
        a = h @ np.linalg.solve(h.T @ h + lam * np.eye(len(c)), h.T)
        brute.append(len(c) * ((y - a @ y) ** 2).sum() / np.trace(np.eye(len(c)) - a) ** 2)
    np.testing.assert_allclose(gcv_scores(h, y, lams), brute, rtol=1e-6)
    fit = rbf_map(c, c, y)
    assert fit.weights.shape == (30, 30)
    np.testing.assert_allclose(fit.weights @ y, y, atol=0.05 * np.abs(y).max())


def test_affine_adaptation_exact_for_global_affine():
    rng = np.random.default_rng(2)
    v = rng.normal(size=(40, 3))
    t = np.array([[i, (i + 1) % 40, (i + 7) % 40] for i in range(40)])
    a = np.array([[1.2, 0.1, 0], [0, 0.8, 0.2], [0.1, 0, 1.5]])
    maps = affine_adaptation(v, v @ a.T + 3.0, t)
    np.testing.assert_allclose(maps, np.broadcast_to(a, maps.shape), atol=1e-8)
    d = rng.normal(size=(40, 3))
    np.testing.assert_allclose(adapt_displacements(maps, d), d @ a.T, atol=1e-8)
    with pytest.raises(ConfigError):
        affine_adaptation(v, v[:-1], t)


def test_affine_adaptation_caps_the_gain_of_a_part_moved_off_the_centre():
    """A patch moved whole (a heavy face's chin further back than the generic one's) is no stretch of it, but the
    paper's maps, measured from the model centre, read it as one: a triangle nearly in line with the centre maps
    a displacement many times longer (the old heavy man's jawOpen 4.4x, the field's lower lip 1.3 IOD at /a/).
    ``max_gain`` lowers each map's singular values above it (times the models' size ratio), keeps its directions,
    and leaves every map within it as it was, to the bit."""
    rng = np.random.default_rng(5)
    v = rng.normal(size=(60, 3))
    t = np.array([[i, (i + 1) % 60, (i + 5) % 60] for i in range(60)])
    shifted = v.copy()
    shifted[:12] += np.array([0.0, 0.0, -0.8])  # one region moved back, unstretched
    loose = affine_adaptation(v, shifted, t, max_cond=30.0)
    capped = affine_adaptation(v, shifted, t, max_cond=30.0, max_gain=2.0)
    x, y = v - v.mean(0), shifted - shifted.mean(0)
    ratio = np.sqrt((y**2).sum(1).mean() / (x**2).sum(1).mean())
    before = np.linalg.svd(loose, compute_uv=False)[:, 0]
    assert before.max() > 2.5 * ratio  # the paper's maps: a gain of 2.9 for a shift
    after = np.linalg.svd(capped, compute_uv=False)
    assert after[:, 0].max() <= 2.0 * ratio * (1 + 1e-9)
    within = before <= 2.0 * ratio
    assert within.any() and (capped[within] == loose[within]).all()
    # Directions kept: each capped map's leading singular vectors are the loose map's.
    over = np.flatnonzero(~within)
    u0, _, vt0 = np.linalg.svd(loose[over])
    u1, _, vt1 = np.linalg.svd(capped[over])
    np.testing.assert_allclose(np.abs(np.einsum("ni,ni->n", u0[:, :, 0], u1[:, :, 0])), 1.0, atol=1e-9)
    np.testing.assert_allclose(np.abs(np.einsum("ni,ni->n", vt0[:, 0], vt1[:, 0])), 1.0, atol=1e-9)


@pytest.mark.parametrize("dense", [False, True])
def test_rig_displacements_equal_the_sparse_chain(dense):
    import scipy.sparse as sp

    from realtime_core.face import FaceModel, MouthCalibration, Rig

    rng = np.random.default_rng(5)
    n_h, n_s = 50, 12
    g = rng.random((n_h, n_s)) if dense else sp.random(n_h, n_s, density=0.2, random_state=5).toarray()
    s = sp.kron(sp.csr_matrix(g), sp.identity(3), format="csr")
    basis = rng.normal(size=(n_s * 3, 4))
    rig = Rig(
        neutral=rng.normal(size=(n_h, 3)),
        triangles=np.zeros((0, 3), np.int32),
        moving=np.arange(n_h),
        matrix=s,
        basis=basis,
        control=np.arange(n_s),
        simple=FaceModel(vertices=rng.normal(size=(n_s, 3)), triangles=np.zeros((0, 3), int)),
        calibration=MouthCalibration(groups=(("a",), ("b",), ("c",), ("d",)), response=np.eye(4), matrix=np.eye(4)),
    )
    p = np.array([0.1, -0.2, 0.3, 0.05])
    np.testing.assert_allclose(rig.displacements(p), (g @ (basis @ p).reshape(n_s, 3)), rtol=1e-4, atol=1e-5)
    assert not rig.displacements(np.zeros(4)).any()


def test_recalibrate_makes_the_head_show_the_requested_parameters():
    """A head whose lips move half as far as asked (as eq. 10 with beta 0.5 can do) is corrected."""
    import scipy.sparse as sp

    from realtime_core.face import FaceModel, MouthCalibration, MouthLandmarks, Rig
    from realtime_core.face.rig import head_response, recalibrate

    v = np.array(
        [
            [1.3, 1, 0],
            [0.7, 1, 0],
            [-1.3, 1, 0],
            [-0.7, 1, 0],
            [0, -0.9, 0.1],
            [0, -1.1, 0.1],
            [0, -0.98, 0.05],
            [0, -1.02, 0.05],
            [0.5, -1, 0],
            [-0.5, -1, 0],
        ],
        dtype=float,
    )
    lm = MouthLandmarks(
        upper_lip=4,
        lower_lip=5,
        upper_inner=6,
        lower_inner=7,
        corner_left=8,
        corner_right=9,
        eye_outer_left=0,
        eye_inner_left=1,
        eye_outer_right=2,
        eye_inner_right=3,
    )
    # Simple model = the head itself; basis: unit params move the right vertices by IOD (= 2) units.
    basis = np.zeros((30, 4))
    basis[3 * 4 + 1, 0] = 2.0  # upper lip up
    basis[3 * 8 + 0, 1], basis[3 * 9 + 0, 1] = 1.0, -1.0  # corners apart: width + 2
    basis[3 * 7 + 1, 2], basis[3 * 5 + 1, 2] = -2.0, -2.0  # lower lip down
    basis[3 * 8 + 1, 3], basis[3 * 9 + 1, 3] = -2.0, -2.0  # corners down
    half = sp.identity(30, format="csr") * 0.5
    rig = Rig(
        neutral=v,
        triangles=np.zeros((0, 3), np.int32),
        moving=np.arange(10),
        matrix=half,
        basis=basis,
        control=np.arange(10),
        simple=FaceModel(vertices=v, triangles=np.zeros((0, 3), int)),
        calibration=MouthCalibration(groups=(("a",), ("b",), ("c",), ("d",)), response=np.eye(4), matrix=np.eye(4)),
    )
    r = head_response(rig, lm)
    assert np.all(np.abs(np.diag(r) - 0.5) < 0.05)  # the head shows about half of what was asked
    fixed = recalibrate(rig, lm)
    assert fixed.meta["head_calibration"] == "applied"
    np.testing.assert_allclose(head_response(fixed, lm), np.eye(4), atol=0.02)
    # open_depress_left: the corners are not pulled down to cancel the depress an opening shows. Here the outer
    # lower-lip midpoint drops with the inner one, so a gap of 1 IOD lowers the outer midpoints' mean by 0.5 IOD
    # with the corners still: lip_corner_depress -0.5 per unit of mouth_open, the rest corrected as before.
    left = recalibrate(rig, lm, open_depress_left=True)
    want = np.eye(4)
    want[3, 2] = -0.5
    np.testing.assert_allclose(head_response(left, lm), want, atol=0.02)
    assert left.meta["open_depress_left"] == pytest.approx(r[3, 2], abs=1e-4)
