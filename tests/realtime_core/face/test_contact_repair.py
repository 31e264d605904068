"""The lips' non-interpenetration constraint (an invariant over any parameters) and the fold repair."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from realtime_core.face import FaceModel, MouthCalibration, MouthLandmarks, Rig
from realtime_core.face.repair import MAX_ROUNDS, PATIENCE, repair_folds


def _lip_rig(seed: int = 3) -> Rig:
    """A strip of 2 x 12 lip columns (upper row y = 0, lower row y = 0 too: a cut seam), the rest of
    a small grid still, and a random dense basis: any parameter vector may push the rows across."""
    rng = np.random.default_rng(seed)
    k = 12
    x = np.linspace(-1, 1, k)
    upper = np.column_stack([x, np.zeros(k), np.zeros(k)])
    lower = upper.copy()
    still = rng.normal(size=(6, 3)) + np.array([0.0, 3.0, 0.0])
    neutral = np.vstack([upper, lower, still])
    n_s = 5
    g = np.zeros((2 * k, n_s))
    g[:k, :2] = rng.random((k, 2))  # upper lip follows simple vertices 0, 1
    g[k:, 2:] = rng.random((k, 3))  # lower lip follows 2, 3, 4
    s = sp.kron(sp.csr_matrix(g), sp.identity(3), format="csr")
    return Rig(
        neutral=neutral,
        triangles=np.zeros((0, 3), np.int32),
        moving=np.arange(2 * k),
        matrix=s,
        basis=rng.normal(size=(n_s * 3, 4)),
        control=np.arange(n_s),
        simple=FaceModel(vertices=rng.normal(size=(n_s, 3)), triangles=np.zeros((0, 3), int)),
        calibration=MouthCalibration(groups=(("a",), ("b",), ("c",), ("d",)), response=np.eye(4), matrix=np.eye(4)),
        contact=np.column_stack([np.arange(k), np.arange(k, 2 * k)]),
        contact_up=np.array([0.0, 2.0, 0.0]),  # not unit: the rig normalises it
    )


RIG = _lip_rig()
PARAM = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=300, deadline=None)
@given(st.lists(PARAM, min_size=4, max_size=4))
def test_lips_never_cross_at_any_parameters(p):
    v = RIG.deformed(np.array(p))
    c = RIG.contact
    gap = v[c[:, 0], 1] - v[c[:, 1], 1]
    scale = 1.0 + float(np.abs(v).max())
    assert gap.min() >= -1e-5 * scale
    # Only the lip columns are touched: the linear part is kept everywhere else, and the correction
    # is vertical and symmetric (the two sides move apart by the same amount).
    push = RIG.contact_push(np.array(p))
    assert not push[:, [0, 2]].any()
    np.testing.assert_allclose(push[c[:, 0], 1], -push[c[:, 1], 1], atol=1e-5 * scale)


def test_no_crossing_no_push():
    """Lips that open (lower below upper) are left exactly as the linear field puts them."""
    rig = RIG
    for p in np.random.default_rng(0).normal(size=(50, 4)):
        lin = (rig.matrix @ (rig.basis @ p.astype(np.float32))).reshape(-1, 3)
        v = rig.neutral[rig.moving] + lin
        c = rig.contact
        if (v[c[:, 0], 1] >= v[c[:, 1], 1]).all():
            np.testing.assert_array_equal(rig.displacements(p), lin)


def _grid(n: int = 9):
    xs, ys = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    v = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(n * n)])
    t = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            t += [[a, a + 1, a + n], [a + 1, a + n + 1, a + n]]
    return v, np.array(t)


def test_fold_repair_unfolds_a_pinned_spike():
    """One vertex pinned to a simple vertex that moves it across its neighbours folds the grid; the
    repair leaves no flipped triangle at that motion (and at its half) and keeps the boundary still."""
    v, t = _grid()
    n = len(v)
    centre = n // 2
    g = sp.csr_matrix(([1.0], ([centre], [0])), shape=(n, 1))
    motion = np.array([[[0.3, 0.0, 0.0]]])  # 2.4 grid cells sideways: the neighbours flip

    def flips(weights, m):
        v1 = v + weights @ m
        n0 = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
        n1 = np.cross(v1[t[:, 1]] - v1[t[:, 0]], v1[t[:, 2]] - v1[t[:, 0]])
        return int((np.einsum("ij,ij->i", n0, n1) < 0).sum())

    assert flips(g, motion[0]) > 0
    edge = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    res = repair_folds(v, t, g, np.concatenate([motion, 0.5 * motion]), fixed=edge)
    assert res.flips_left == 0
    assert flips(res.weights, motion[0]) == 0 and flips(res.weights, 0.5 * motion[0]) == 0
    assert not res.weights[np.flatnonzero(edge)].count_nonzero()
    # The motion is spread, not removed: the pinned vertex still moves most.
    w = np.asarray(res.weights.todense()).ravel()
    assert w.argmax() == centre and w.max() > 0.1


def test_fold_repair_counts_stretch_only_at_the_first_stretch_poses():
    """A vertex pulled straight up out of the grid stretches its edges (no triangle flips): counted at the first
    pose, the repair smooths it; given as a later pose past ``stretch_poses`` (an expression pose, where rigging
    repairs folds only), it leaves the field as it was; a fold there is still repaired."""
    v, t = _grid()
    n = len(v)
    centre = n // 2
    g = sp.csr_matrix(([1.0], ([centre], [0])), shape=(n, 1))
    still, up = np.zeros((1, 1, 3)), np.array([[[0.0, 0.0, 1.0]]])  # 8 cells up: edges 8x their length
    assert repair_folds(v, t, g, np.concatenate([up, still])).rounds > 0
    kept = repair_folds(v, t, g, np.concatenate([still, up]), stretch_poses=1)
    assert kept.rounds == 0 and (kept.weights != g).nnz == 0
    side = np.array([[[0.3, 0.0, 0.0]]])  # a fold (test above)
    assert repair_folds(v, t, g, np.concatenate([still, side]), stretch_poses=1).rounds > 0


def test_fold_repair_ignores_folds_of_faces_it_is_told_are_not_seen():
    """Faces about to be removed (a hollow head's hidden inner lip walls) must not steer the repair: a fold
    made only of unmeasured faces leaves the field as it is (the repair once spent its 200 rounds on such
    folds and left a stretched edge on the faces that stay); measured, the same fold is smoothed away."""
    v, t = _grid()
    n = len(v)
    centre = n // 2
    g = sp.csr_matrix(([1.0], ([centre], [0])), shape=(n, 1))
    motion = np.array([[[0.3, 0.0, 0.0]]])  # folds the faces round the centre (and stretches their edges)
    edge = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    # Every face within two rings of the centre: their edges are the only ones the motion changes.
    ring = np.zeros(n, dtype=bool)
    ring[centre] = True
    for _ in range(2):
        ring[np.unique(t[ring[t].any(axis=1)])] = True
    hidden = ring[t].any(axis=1)
    res = repair_folds(v, t, g, motion, fixed=edge, measured=~hidden)
    assert res.rounds == 0 and (res.weights != g).nnz == 0
    res = repair_folds(v, t, g, motion, fixed=edge)
    assert res.rounds > 0 and res.flips_left == 0


def test_fold_repair_moves_sliver_clusters_as_one():
    """A vertex 0.2% of an edge away from another (a scan's sliver fan) flips its tiny triangles at
    the smallest motion difference; the repair ties the two together (equal rows), so they move as
    one and nothing flips, while the rest of the field keeps its motion."""
    v, t = _grid()
    n = len(v)
    a = n // 2
    f = int(np.flatnonzero((t == a).any(axis=1))[0])
    b, c = (x for x in t[f] if x != a)
    p = v[a] + 0.002 * (v[t[f]].mean(axis=0) - v[a])
    v = np.vstack([v, p])
    t = np.vstack([np.delete(t, f, axis=0), [[a, b, n], [b, c, n], [c, a, n]]])
    g = sp.csr_matrix(([1.0, 0.5], ([a, a - 1], [0, 0])), shape=(n + 1, 1))  # p itself is still
    motion = np.array([[[0.0, 0.0, 0.0]]])
    motion[0, 0] = 0.05 * (p - v[a]) / np.linalg.norm(p - v[a])  # a moves past p
    edge = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    res = repair_folds(v, t, g, motion, fixed=edge, tiny=0.2)
    assert res.flips_left == 0
    w = np.asarray(res.weights.todense()).ravel()
    assert w[a] == w[n] and w[a] > 0.3
    v1 = v + res.weights @ motion[0]
    n0 = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n1 = np.cross(v1[t[:, 1]] - v1[t[:, 0]], v1[t[:, 2]] - v1[t[:, 0]])
    assert (np.einsum("ij,ij->i", n0, n1) > 0).all()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-0.5, 0.5), min_size=8, max_size=8))
def test_a_rest_pose_shifts_the_parameters_exactly(values):
    """with_rest_pose: new.deformed(p) == old.deformed(p + rest) (lip push included) for any p, and
    modelled_rest gives the original neutral back."""
    from realtime_core.face.rig import modelled_rest, with_rest_pose

    rig = _lip_rig()
    rest, p = np.array(values[:4]), np.array(values[4:])
    new = with_rest_pose(rig, rest)
    np.testing.assert_allclose(new.deformed(p), rig.deformed(p + rest), atol=2e-5)
    np.testing.assert_allclose(modelled_rest(new), rig.neutral, atol=2e-5)
    np.testing.assert_allclose(modelled_rest(rig), rig.neutral, atol=1e-6)  # (float32)


def _flipped(v: np.ndarray, t: np.ndarray, weights: sp.csr_matrix, motion: np.ndarray) -> int:
    v1 = v + weights @ motion
    n0 = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n1 = np.cross(v1[t[:, 1]] - v1[t[:, 0]], v1[t[:, 2]] - v1[t[:, 0]])
    return int((np.einsum("ij,ij->i", n0, n1) < 0).sum())


def test_fold_repair_unflips_a_thin_corner_triangle_that_smoothing_cannot():
    """A coarse mouth corner: a thin triangle (a, b, c) whose apex c lies 0.02 above its long edge ab (a on
    the lip inward, b beyond the corner, both still), c's other neighbour the upper skin e, pinned to drop
    0.6 (a lip raise pulling the corner down). Uniform smoothing puts c at its neighbours' mean (a third of
    e's drop, 0.2): below ab, flipped, however many rounds. The repair's last phase ties c to ab: 0 flips
    at both poses, c where the edge's linear field puts it, and the pinned skin and jaw (fixed rows) still
    move exactly as their simple vertices ask."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 0.02, 0], [0.5, 1, 0], [0.5, -1, 0]])
    a, b, c, e, d = range(5)
    t = np.array([[a, b, c], [a, c, e], [c, b, e], [a, d, b]])
    g = sp.csr_matrix(([1.0, 1.0, 1.0], ([e, d, c], [0, 1, 0])), shape=(5, 2))  # c follows the skin's drop
    motion = np.array([[[0.0, -0.6, 0.0], [0.0, -0.4, 0.0]]])  # skin down 0.6, jaw down 0.4
    motions = np.concatenate([motion, 0.5 * motion])
    fixed = np.array([True, True, False, True, True])
    assert _flipped(v, t, g, motion[0]) == 1
    smoothed_only = repair_folds(v, t, g, motions, fixed=fixed, tie_rounds=0)
    assert smoothed_only.flips_left == 1 and _flipped(v, t, smoothed_only.weights, motion[0]) == 1
    res = repair_folds(v, t, g, motions, fixed=fixed)
    assert res.flips_left == 0
    assert _flipped(v, t, res.weights, motion[0]) == 0 and _flipped(v, t, res.weights, motions[1]) == 0
    w = res.weights.toarray()
    np.testing.assert_allclose(w[c], 0.5 * w[a] + 0.5 * w[b], atol=1e-12)  # c's projection halves ab
    np.testing.assert_array_equal(w[[a, b, d, e]], g.toarray()[[a, b, d, e]])
    d1 = res.weights @ motion[0]
    np.testing.assert_allclose(d1[e], [0.0, -0.6, 0.0])
    np.testing.assert_allclose(d1[d], [0.0, -0.4, 0.0])


def test_fold_repair_leaves_a_field_smoothing_unfolds_as_smoothing_left_it():
    """The tie phase runs only on flips the smoothing rounds leave: a fold they remove comes out of the
    repair with the very same weights as without that phase (rigs that passed keep their field)."""
    v, t = _grid()
    n = len(v)
    g = sp.csr_matrix(([1.0], ([n // 2], [0])), shape=(n, 1))
    motion = np.array([[[0.3, 0.0, 0.0]]])
    edge = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    with_ties = repair_folds(v, t, g, motion, fixed=edge)
    without = repair_folds(v, t, g, motion, fixed=edge, tie_rounds=0)
    assert with_ties.flips_left == 0 and with_ties.rounds == without.rounds
    assert (with_ties.weights != without.weights).nnz == 0


def test_a_repair_that_cannot_settle_gives_up_after_its_patience_and_says_so():
    """A vertex fixed to a simple vertex that carries it 0.4 across a 15 x 15 grid folds the triangles round it at
    any smoothing (its row is never changed): the count of bad vertices stops falling within a few rounds. With
    ``patience`` the repair ends ``patience`` rounds after its last new low, not settled and with no tie rounds
    (its caller falls back to fewer poses); without, it runs all its rounds and tie rounds. At 41 poses (more than
    the 32 the measurement once batched), its flips left are those a pose-by-pose count finds."""
    v, t = _grid(15)
    n = len(v)
    fixed = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    fixed[n // 2] = True
    g = sp.csr_matrix(([1.0], ([n // 2], [0])), shape=(n, 1))
    motions = np.linspace(0.01, 0.4, 41)[:, None, None] * np.array([[1.0, 0.0, 0.0]])
    full = repair_folds(v, t, g, motions, fixed=fixed)
    assert not full.settled and full.rounds > MAX_ROUNDS
    quick = repair_folds(v, t, g, motions, fixed=fixed, patience=PATIENCE)
    best = quick.bad.index(min(quick.bad)) + 1
    assert not quick.settled and quick.rounds == best + PATIENCE < MAX_ROUNDS // 4
    assert quick.flips_left > 0
    assert quick.flips_left == max(_flipped(v, t, quick.weights, m) for m in motions)
    assert full.flips_left == max(_flipped(v, t, full.weights, m) for m in motions)


def test_a_repair_that_settles_late_still_settles_with_patience():
    """A disc of 37 vertices of a 31 x 31 grid carried 0.4 sideways, edges stretched beyond 1.2x counting as folds:
    the smoothed patch first grows (the count of bad vertices rises from 46 to over 150) and falls below its first
    count only after 30 rounds; it settles in 37. With the repair's patience it settles in the same rounds with the
    same weights (a shorter patience, 25, would have given up)."""
    v, t = _grid(31)
    n = len(v)
    fixed = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    disc = np.flatnonzero(np.linalg.norm(v - v[n // 2], axis=1) < 0.12)
    g = sp.csr_matrix((np.ones(len(disc)), (disc, np.zeros(len(disc), dtype=int))), shape=(n, 1))
    motion = np.array([[[0.4, 0.0, 0.0]]])
    plain = repair_folds(v, t, g, motion, fixed=fixed, max_stretch=1.2)
    assert plain.settled and plain.rounds > 30
    patient = repair_folds(v, t, g, motion, fixed=fixed, max_stretch=1.2, patience=PATIENCE)
    assert patient.settled and patient.rounds == plain.rounds and patient.flips_left == 0
    assert (patient.weights != plain.weights).nnz == 0
    assert not repair_folds(v, t, g, motion, fixed=fixed, max_stretch=1.2, patience=25).settled


def _mouth_with_teeth() -> tuple[Rig, MouthLandmarks, np.ndarray, np.ndarray, np.ndarray]:
    """Two lip strips 0.02 IOD apart (upper rows y = 0.01.., lower rows y = -0.01..) and, behind them, a
    separate strip of upper teeth whose edge is level with the lower lip's inner contour (y = -0.01,
    z = -0.05): in every column the lowest vertex that mouth_open leaves still is a tooth. mouth_open
    drops the lower lip 1 IOD per unit, upper_lip_raise lifts it 1 IOD per unit (a lip corner rising
    with the upper lip); the upper lip and the teeth never move. IOD 1 (eye centres at x = +-0.5, y = 1).
    Returns the rig, its landmarks and the upper lip's, lower lip's and teeth's inner rows."""
    xs = np.linspace(-0.5, 0.5, 11)

    def strip(ys, z):
        v = np.array([[x, y, z] for y in ys for x in xs])
        k = len(xs)
        t = [[r * k + i, r * k + i + 1, (r + 1) * k + i] for r in range(len(ys) - 1) for i in range(k - 1)] + [
            [r * k + i + 1, (r + 1) * k + i + 1, (r + 1) * k + i] for r in range(len(ys) - 1) for i in range(k - 1)
        ]
        return v, np.array(t)

    up_v, up_t = strip([0.01, 0.03, 0.05], 0.0)
    lo_v, lo_t = strip([-0.01, -0.03, -0.05], 0.0)
    th_v, th_t = strip([-0.01, 0.02], -0.05)
    eyes = np.array([[0.6, 1.0, 0.0], [0.4, 1.0, 0.0], [-0.6, 1.0, 0.0], [-0.4, 1.0, 0.0]])
    n_u, n_l, n_t = len(up_v), len(lo_v), len(th_v)
    neutral = np.vstack([up_v, lo_v, th_v, eyes])
    tri = np.vstack([up_t, lo_t + n_u, th_t + n_u + n_l]).astype(np.int32)
    k = len(xs)
    upper_row, lower_row, teeth_row = np.arange(k), n_u + np.arange(k), n_u + n_l + np.arange(k)
    mid = k // 2
    e = n_u + n_l + n_t
    lm = MouthLandmarks(
        upper_lip=2 * k + mid,
        lower_lip=n_u + 2 * k + mid,
        upper_inner=int(upper_row[mid]),
        lower_inner=int(lower_row[mid]),
        corner_left=int(upper_row[-1]),
        corner_right=int(upper_row[0]),
        eye_outer_left=e,
        eye_inner_left=e + 1,
        eye_outer_right=e + 2,
        eye_inner_right=e + 3,
    )
    moving = np.arange(e)
    g = np.zeros((e, 2))
    g[n_u : n_u + n_l, 1] = 1.0  # the lower lip follows simple vertex 1 (the jaw); the rest, 0 (still)
    basis = np.zeros((6, 4))
    basis[4, 0] = 1.0  # upper_lip_raise lifts the jaw vertex (y)
    basis[4, 2] = -1.0  # mouth_open drops it
    rig = Rig(
        neutral=neutral,
        triangles=tri,
        moving=moving,
        matrix=sp.kron(sp.csr_matrix(g), sp.identity(3), format="csr"),
        basis=basis,
        control=np.arange(2),
        simple=FaceModel(vertices=np.zeros((2, 3)), triangles=np.zeros((0, 3), int)),
        calibration=MouthCalibration(groups=(("a",), ("b",), ("c",), ("d",)), response=np.eye(4), matrix=np.eye(4)),
    )
    return rig, lm, upper_row, lower_row, teeth_row


def test_lip_columns_pair_the_lips_never_a_tooth_and_push_only_lips_that_cross():
    """Separate teeth behind the lips are not lips: every column pairs the upper lip's inner row with the
    lower lip's (the rule without the lips' own pieces picks the tooth in every column), so a lower lip
    lifted in front of the teeth but short of the upper lip is left exactly where the field puts it
    (before: pushed down as if it crossed), and one lifted past the upper lip is pushed back to touching."""
    import dataclasses

    from realtime_core.face.model import face_frame
    from realtime_core.face.rig import contact_spread, lip_columns, lip_pairs_by_drop

    rig, lm, upper_row, lower_row, teeth_row = _mouth_with_teeth()
    frame = face_frame(rig.neutral, lm)
    pairs = lip_columns(rig, lm, frame, column_width=0.05)
    inner = set(zip(upper_row[1:-1].tolist(), lower_row[1:-1].tolist(), strict=True))
    assert {tuple(p) for p in pairs.tolist()} == inner  # 9 columns strictly between the corners
    # What the rule gives when every vertex in the box may stand for a lip: the teeth.
    drop = np.zeros(len(rig.neutral))
    drop[rig.moving] = -rig.displacements(np.array([0.0, 0.0, 1.0, 0.0]))[:, 1]
    old = lip_pairs_by_drop(rig.neutral, drop, lm, frame, column_width=0.05)
    assert np.isin(old[:, 0], teeth_row).sum() == 9

    def with_contact(c):
        r = dataclasses.replace(rig, contact=c, contact_up=frame.axes[1])
        return dataclasses.replace(r, contact_spread=contact_spread(r, iod=frame.iod))

    new_rig, old_rig = with_contact(pairs), with_contact(old)
    lift = np.array([0.015, 0.0, 0.0, 0.0])  # the lower lip 0.015 up: 0.005 below the upper lip
    linear = (rig.matrix @ (rig.basis @ lift.astype(np.float32))).reshape(-1, 3)
    np.testing.assert_array_equal(new_rig.displacements(lift), linear)
    # The tooth pairs dragged the lip down by half the 0.015 it rose above the teeth's edge (half each way).
    np.testing.assert_allclose(old_rig.contact_push(lift)[lower_row[1:-1], 1], -0.0075, atol=1e-6)
    past = np.array([0.05, 0.0, 0.0, 0.0])  # 0.03 past the upper lip: pushed apart to touching
    v = new_rig.deformed(past)
    np.testing.assert_allclose(v[upper_row[1:-1], 1], v[lower_row[1:-1], 1], atol=1e-6)


def _lip_over_jaw():
    """A 9 x 9 grid: rows y >= 0.5 an upper lip following simple vertex 0 (still), the rest a jaw following simple
    vertex 1, except one jaw vertex just below the lip pinned far up (simple vertex 2): the grid folds round it
    at its motion, and the repair smooths the rows there, the lip's among them. Returns v, t, weights, motion,
    the lip's vertices, the boundary."""
    v, t = _grid()
    n = len(v)
    lip = v[:, 1] >= 0.5
    spike = int(np.flatnonzero((np.abs(v[:, 0] - 0.5) < 1e-9) & (np.abs(v[:, 1] - 0.375) < 1e-9))[0])
    g = np.zeros((n, 3))
    g[lip, 0] = 1.0
    g[~lip, 1] = 1.0
    g[spike] = [0.0, 0.0, 1.0]
    motion = np.array([[[0.0, 0.0, 0.0], [0.0, -0.2, 0.0], [0.0, 0.4, 0.0]]])
    edge = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    return v, t, sp.csr_matrix(g), motion, lip, edge


def test_an_own_side_takes_no_motion_from_its_other_neighbours():
    """Smoothed over every neighbour, the lip's rows beside the fold take the jaw's and the spike's motion (the
    coarse upper lip that dropped with the jaw); smoothed over each other only (``own_side``), the lip's rows keep
    weighing its own simple vertex alone, and the fold still goes (the jaw's side gives way)."""
    v, t, g, motion, lip, edge = _lip_over_jaw()
    everyone = repair_folds(v, t, g, motion, fixed=edge)
    assert everyone.flips_left == 0
    assert np.abs(everyone.weights.toarray()[lip][:, 1:]).max() > 0.01
    own = repair_folds(v, t, g, motion, fixed=edge, own_side=lip)
    assert own.flips_left == 0
    w = own.weights.toarray()
    np.testing.assert_array_equal(w[lip][:, 1:], 0.0)
    np.testing.assert_allclose(w[lip][:, 0], 1.0)


def test_a_tied_vertex_moves_as_its_vertex_through_the_repair():
    """``ties``: the vertex takes its vertex's row from the start and keeps it while the smoothing changes that
    row (the spike's own row is smoothed, and the vertex tied to it follows), and the fold still goes."""
    v, t, g, motion, _, edge = _lip_over_jaw()
    spike = int(np.flatnonzero(g.toarray()[:, 2])[0])
    left = spike - 1  # its neighbour in the same grid row
    res = repair_folds(v, t, g, motion, fixed=edge, ties={left: spike})
    assert res.flips_left == 0
    w = res.weights.toarray()
    np.testing.assert_allclose(w[left], w[spike], atol=1e-6)
    assert not np.allclose(w[spike], [0.0, 0.0, 1.0])  # the row it follows was smoothed


def test_a_stubborn_folds_patch_widens_ring_after_ring_and_settles():
    """A vertex fixed to a simple vertex that carries it 2.5 grid cells along a diagonal folds the two triangles
    beside it, and only them: no other vertex is ever on a fold, so the plain repair's patch, which grows only
    through vertices that were on a fold themselves, stays one ring wide round them; their fill from that ring folds
    again however long it runs, and the tie rounds leave 2 flips (the once-subdivided Lee Perry-Smith's copy: 2 chin
    flips). Widened (``widen``: one more ring for every ``grow_every`` rounds), the patch spreads the motion over
    enough of the grid to unfold it: settled long before the rounds run out, 0 flips by an independent count."""
    v, t = _grid(15)
    n = len(v)
    fixed = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    fixed[n // 2] = True
    g = sp.csr_matrix(([1.0], ([n // 2], [0])), shape=(n, 1))
    cell = 1.0 / 14
    motion = (2.5 * cell * np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0))[None, None, :]
    plain = repair_folds(v, t, g, motion, fixed=fixed)
    assert not plain.settled and plain.rounds > MAX_ROUNDS and _flipped(v, t, plain.weights, motion[0]) > 0
    wide = repair_folds(v, t, g, motion, fixed=fixed, widen=True)
    assert wide.settled and wide.rounds < MAX_ROUNDS // 2 and wide.flips_left == 0
    assert _flipped(v, t, wide.weights, motion[0]) == 0
    # Wider than the plain patch (its rows: the folded vertices and one ring), the fixed rows untouched.
    assert wide.smoothed_rows > 2 * plain.smoothed_rows
    assert not (wide.weights[np.flatnonzero(fixed)] != g[np.flatnonzero(fixed)]).nnz
    # The motion is spread, not removed: the pinned vertex still moves most.
    w = np.asarray(wide.weights.todense()).ravel()
    assert w.argmax() == n // 2


def test_eased_field_smooths_a_pinned_kink_keeps_the_rest_and_takes_only_its_own_side() -> None:
    """A grid whose field is a tent across x (rows 1 - |x|, |x| of a still and a dropping simple vertex: a kink in the
    middle, the upper lip drawn to a peak) over a lower strip that follows a third (the jaw): eased with weight 1 inside
    the upper grid and 0 on its border, the kink flattens, every row still sums to 1, the border's rows are the same to
    the bit, and with ``among`` the upper grid only, no eased row takes the jaw's motion (without it, the rows beside
    the lower strip do)."""
    from realtime_core.face.rig import eased_field
    from tests.grids import grid_triangles

    cols, rows = 21, 7
    xs = np.linspace(-1.0, 1.0, cols)
    gx, gy = np.meshgrid(xs, np.linspace(0.0, 0.6, rows))
    upper = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]
    lower = upper[:cols] - np.array([0.0, 0.1, 0.0])  # one row under the upper grid's bottom row, joined to it
    neutral = np.vstack([upper, lower])
    n_u = len(upper)
    tri = [grid_triangles(rows, cols)]
    for i in range(cols - 1):  # the strip joined to the bottom row
        tri.append(np.array([[n_u + i, n_u + i + 1, i + 1], [n_u + i, i + 1, i]]))
    tri_all = np.vstack(tri).astype(np.int32)
    g = np.zeros((len(neutral), 3))
    ax = np.abs(np.tile(xs, rows))
    g[:n_u, 0], g[:n_u, 1] = 1.0 - ax, ax
    g[n_u:, 2] = 1.0
    basis = np.zeros((9, 4))
    basis[4, 2] = -1.0  # mouth_open drops simple vertex 1 (the lip's sides)
    basis[7, 2] = -2.0  # and the jaw (simple vertex 2) twice as far
    rig = Rig(
        neutral=neutral,
        triangles=tri_all,
        moving=np.arange(len(neutral)),
        matrix=sp.kron(sp.csr_matrix(g), sp.identity(3), format="csr"),
        basis=basis,
        control=np.array([cols // 2, 0, n_u]),
        simple=FaceModel(vertices=np.zeros((3, 3)), triangles=np.zeros((0, 3), int)),
        calibration=MouthCalibration(groups=(("a",), ("b",), ("c",), ("d",)), response=np.eye(4), matrix=np.eye(4)),
    )
    border = np.zeros(len(neutral), dtype=bool)
    border[:n_u] = (np.abs(upper[:, 0]) == 1.0) | (upper[:, 1] == 0.6)
    border[n_u:] = True
    weight = np.where(border, 0.0, 1.0)
    own = np.r_[np.ones(n_u, dtype=bool), np.zeros(len(lower), dtype=bool)]
    p = np.array([0.0, 0.0, 1.0, 0.0])
    row = 3 * cols + np.arange(cols)  # a middle row of the upper grid

    def kink(r: Rig) -> float:
        dy = r.deformed(p)[row, 1] - neutral[row, 1]
        mid = cols // 2
        return float(0.5 * (dy[mid - 1] + dy[mid + 1]) - dy[mid])  # the tent's corner: its neighbours below it

    eased = eased_field(rig, weight, rounds=20, among=own)
    mixed = eased_field(rig, weight, rounds=20)
    assert kink(rig) == pytest.approx(-0.1, abs=1e-6)
    assert abs(kink(eased)) < 0.5 * abs(kink(rig))
    w_new = eased.matrix.tocsr()[0::3][:, 0::3].toarray()
    moving_rows = np.zeros((len(neutral), 3))
    moving_rows[eased.moving] = w_new
    assert np.allclose(moving_rows.sum(axis=1), 1.0)
    assert np.array_equal(eased.deformed(p)[border], rig.deformed(p)[border])
    assert np.all(moving_rows[:n_u, 2] == 0.0)  # the jaw's motion stays out of the upper grid
    mixed_rows = np.zeros((len(neutral), 3))
    mixed_rows[mixed.moving] = mixed.matrix.tocsr()[0::3][:, 0::3].toarray()
    assert mixed_rows[cols + cols // 2, 2] > 0.01  # next to the strip, among all neighbours: it does


def test_a_repair_whose_rounds_run_out_reports_the_flips_of_the_weights_it_returns():
    """The pinned spike of the first test, given one, two, ... rounds and no tie rounds: the rounds run out right
    after a smoothing, and the flips reported are those of the returned weights (counted here pose by pose), not
    the count before that last smoothing (which stayed above it while the spike unfolded)."""
    v, t = _grid()
    n = len(v)
    g = sp.csr_matrix(([1.0], ([n // 2], [0])), shape=(n, 1))
    motion = np.array([[[0.3, 0.0, 0.0]]])
    edge = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    before = _flipped(v, t, g, motion[0])
    reported, counted = [], []
    for rounds in range(1, 6):
        res = repair_folds(v, t, g, motion, fixed=edge, max_rounds=rounds, tie_rounds=0)
        reported.append(res.flips_left)
        counted.append(_flipped(v, t, res.weights, motion[0]))
    assert reported == counted
    assert counted[0] < before  # the first round already unfolds some: a stale count would say `before`


def test_one_round_replaces_the_folded_rows_and_one_ring_by_their_neighbours_mean_twice():
    """The documented round, computed here with whole sparse matrices: the vertices of the flipped triangles and
    one ring round them (not the fixed ones) take the mean of their mesh neighbours' rows, twice (Jacobi steps);
    every other row is returned exactly. The repair rewrites only the rows it changes (a dense copy, row blocks):
    it must give these very numbers."""
    v, t = _grid()
    n = len(v)
    rng = np.random.default_rng(5)
    dense = rng.random((n, 3)) * (rng.random((n, 3)) < 0.3)
    dense[n // 2] = [1.0, 0.0, 0.5]
    g = sp.csr_matrix(dense)
    motion = np.zeros((1, 3, 3))
    motion[0, 0] = [0.3, 0.0, 0.0]  # simple vertex 0 carries the centre 2.4 cells sideways: folds round it
    edge = (v[:, 0] == 0) | (v[:, 0] == 1) | (v[:, 1] == 0) | (v[:, 1] == 1)
    v1 = v + g @ motion[0]
    n0 = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n1 = np.cross(v1[t[:, 1]] - v1[t[:, 0]], v1[t[:, 2]] - v1[t[:, 0]])
    flipped = np.einsum("ij,ij->i", n0, n1) < 0
    assert flipped.any()
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    length, rest = (np.linalg.norm(p[e[:, 0]] - p[e[:, 1]], axis=1) for p in (v1, v))
    stretched = length > 3.0 * rest
    bad = np.zeros(n, dtype=bool)
    bad[t[flipped].ravel()] = True
    bad[e[stretched].ravel()] = True
    adj = sp.csr_matrix((np.ones(len(e) * 2), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n))
    adj.data[:] = 1.0  # each neighbour once (every inner edge is on two triangles)
    sel = (bad | (adj @ bad.astype(float) > 0)) & ~edge
    mean = sp.diags(1.0 / np.asarray(adj.sum(axis=1)).ravel()) @ adj
    keep, pick = sp.diags((~sel).astype(float)), sp.diags(sel.astype(float))
    want = g
    for _ in range(2):
        want = keep @ want + pick @ (mean @ want)
    want = want.toarray()
    want[np.abs(want) < 1e-6] = 0.0
    res = repair_folds(v, t, g, motion, fixed=edge, max_rounds=1, tie_rounds=0)
    np.testing.assert_array_equal(res.weights.toarray(), want)
    assert res.smoothed_rows == int(sel.sum())


def test_the_compiled_fold_measure_decides_as_numpy_does():
    """The repair's compiled flip and stretch tests (realtime_core.face.compiled) against numpy's arithmetic as the
    repair used it before (np.cross, einsum, np.linalg.norm on (triangles, poses, 3) arrays): the same decisions
    for every triangle, pose and edge, including triangles flattened to nearly zero area at some pose (where a
    different order of operations could change the sign) and edges at exactly their limit."""
    from realtime_core.face.compiled import flipped_at_poses, stretched_at_poses

    rng = np.random.default_rng(7)
    v, t = _grid(9)
    n, m, n_poses = len(v), len(t), 45
    disp = rng.normal(scale=0.08, size=(n, 3 * n_poses))
    # Pose 3 puts every vertex on one line through the origin (zero area in exact arithmetic: signs by rounding).
    disp[:, 9:12] = rng.uniform(size=(n, 1)) * np.array([0.3, 0.7, 0.1]) - v
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]).astype(np.int64)
    n0 = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    pos = v[:, None, :] + disp.reshape(n, n_poses, 3)
    longest = 2.5 * np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    longest[::5] = np.linalg.norm(pos[e[::5, 0], 2] - pos[e[::5, 1], 2], axis=1)  # exactly reached at pose 2
    which_t, which_e = np.arange(m)[::2], np.arange(len(e))[1::2]
    pa, pb, pc = (pos[t[which_t, k]] for k in range(3))
    want_flip = np.einsum("kj,kpj->kp", n0[which_t], np.cross(pb - pa, pc - pa)) < 0
    d = pos[e[which_e, 0], :30] - pos[e[which_e, 1], :30]
    want_stretch = (np.linalg.norm(d, axis=2) > longest[which_e, None]).any(axis=1)
    flipped = np.zeros((m, n_poses), dtype=bool)
    stretched = np.ones(len(e), dtype=bool)
    flipped_at_poses(v, disp, t.astype(np.int64), n0, which_t, flipped)
    stretched_at_poses(v, disp, e, longest, which_e, 30, stretched)
    assert np.array_equal(flipped[which_t], want_flip) and not flipped[1::2].any()
    assert 0 < want_flip.sum() < want_flip.size and 0 < want_flip[:, 3].sum() < len(which_t)
    assert np.array_equal(stretched[which_e], want_stretch) and stretched[::2].all()
    assert 0 < want_stretch.sum() < len(which_e)
