"""A scan's inner-mouth pieces follow the jaw below the mouth line (:func:`assets.heads.parts.inner_mouth_weights`,
:func:`assets.heads.parts.with_jaw_weights`): the weights on a synthetic mesh, the rows on the built-in rig."""

from __future__ import annotations

import numpy as np
import pytest

from assets.heads.parts import JAW_FULL, SEAM_RAMP, inner_mouth_weights, with_jaw_weights
from tests.grids import patch as _patch
from tests.grids import stacked


def test_only_pieces_inside_the_mouth_follow_the_jaw_rising_below_the_mouth_line():
    """A face sheet (z = 0; mouth corners at (+-0.5, 0), chin at y = -1, nose tip at y = 0.6; IOD 1) and
    separate pieces: one behind the mouth reaching from above the mouth line to below it (the inner-mouth
    piece), one as far back but 1.6 to the side (an ear), one below the chin (the bust), one poking out in
    front of the corners, one behind the mouth in another part (teeth). Only the first is weighted, each
    of its vertices by its depth below the mouth line: 0 above, -y / (JAW_FULL * 1) below, at most 1."""
    xs, ys = np.meshgrid(np.linspace(-2, 2, 21), np.linspace(-2, 2, 21))
    face = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    ft = _patch(-2, 2, -2, 2, 0, 0, n=21)[1]
    pieces = {
        "inner": _patch(-0.3, 0.3, -0.8, 0.3, -0.3, -0.2),
        "ear": _patch(1.4, 1.8, -0.6, 0.2, -0.5, -0.5),
        "bust": _patch(-0.3, 0.3, -1.6, -1.2, -0.3, -0.3),
        "front": _patch(-0.3, 0.3, -0.6, 0.0, -0.2, 0.1),
        "teeth": _patch(-0.3, 0.3, -0.5, 0.0, -0.1, -0.1),
    }
    v, t, at = stacked(face, ft, pieces)
    n = len(v)
    part = np.zeros(n, dtype=np.int64)
    part[at["teeth"]] = 1

    def near(p):
        return int(np.argmin(np.linalg.norm(face - p, axis=1)))

    lm = {"corner_left": near([0.5, 0, 0]), "corner_right": near([-0.5, 0, 0]), "chin": near([0, -1, 0])}
    lm["nose_tip"] = near([0, 0.6, 0])
    w = inner_mouth_weights(v, t, part, lm, np.eye(3), 1.0)

    y = v[at["inner"], 1]
    np.testing.assert_allclose(w[at["inner"]], np.clip(-y / JAW_FULL, 0, 1), atol=1e-12)
    assert (w[at["inner"]] == 1).any() and (w[at["inner"]] == 0).any()  # both ends of the ramp are there
    others = np.setdiff1d(np.arange(n), at["inner"])
    assert not w[others].any()
    # Without parts, the teeth patch is a piece of the face's part like any other: weighted too.
    w2 = inner_mouth_weights(v, t, None, lm, np.eye(3), 1.0)
    np.testing.assert_allclose(w2[at["teeth"]], np.clip(-v[at["teeth"], 1] / JAW_FULL, 0, 1), atol=1e-12)


def test_an_inner_piece_joined_to_the_face_by_a_texture_seam_takes_one_weight_per_position_blended_across_it():
    """A face sheet (as above) with a lip's inner wall joined to it by its edges, running back to z = -0.2 below the
    mouth line, and a lining that continues the wall down behind the chin but whose vertices along the wall's lower
    edge are copies (a texture seam: same positions, other indices), as Lee Perry-Smith's inside of the mouth. On
    the mesh as loaded the lining is a piece of its own: its seam copies took the height's weight while the wall's
    kept 0, and at /a/ the seam's two sides parted (0.12-0.23 IOD on the scan; docs/animation.md, "The seam tear
    at the right depth"). Now every position has one weight, the height's times a blend: 0.5 at the seam, rising to 1
    SEAM_RAMP along the lining and falling to 0 SEAM_RAMP up the wall (each row's distance from the seam computed
    here from the patches' row spacing). A piece truly apart (no shared position) is weighted by its height alone.
    Positions given as ``still`` take 0 on every copy (the seam's lining copy too) and leave every other weight as it
    was: the upper lip's contact row that sagged below the corners' line took a trace of the jaw and turned a corner
    wall over (test_knife.py, the 1,500-triangle copy)."""
    xs, ys = np.meshgrid(np.linspace(-2, 2, 21), np.linspace(-2, 2, 21))
    face = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    ft = _patch(-2, 2, -2, 2, 0, 0, n=21)[1]

    def near(p):
        return int(np.argmin(np.linalg.norm(face - p, axis=1)))

    # The wall: 5 columns from x = -0.2 to 0.2, from the face's row y = 0 (the face's own vertices at x = -0.2, 0,
    # 0.2) to z = -0.2.
    wv, wt = _patch(-0.2, 0.2, 0.0, -0.1, 0.0, -0.2, n=5)
    wall_index = len(face) + np.arange(len(wv))
    wall_index[[0, 2, 4]] = [near([x, 0.0, 0.0]) for x in (-0.2, 0.0, 0.2)]
    v = np.vstack([face, wv])
    t = np.vstack([ft, wall_index[wt]])
    wall_bottom = wall_index[-5:]
    # The lining, 5 rows: from the wall's lower edge (copies of its vertices) down to y = -0.8, z = -0.3.
    lv, lt = _patch(-0.2, 0.2, -0.1, -0.8, -0.2, -0.3, n=5)
    lining = len(v) + np.arange(len(lv))
    v, t = np.vstack([v, lv]), np.vstack([t, lt + len(v)])
    np.testing.assert_array_equal(v[lining[:5]], v[wall_bottom])  # the seam: coincident copies
    apart_v, apart_t = _patch(0.6, 0.9, -0.2, -0.7, -0.4, -0.5)  # a piece truly apart, behind the mouth
    apart = len(v) + np.arange(len(apart_v))
    v, t = np.vstack([v, apart_v]), np.vstack([t, apart_t + len(v)])
    lm = {"corner_left": near([0.5, 0, 0]), "corner_right": near([-0.5, 0, 0]), "chin": near([0, -1, 0])}
    lm["nose_tip"] = near([0, 0.6, 0])

    w = inner_mouth_weights(v, t, None, lm, np.eye(3), 1.0)

    def height(i):
        return np.clip(-v[i, 1] / JAW_FULL, 0, 1)

    for i, j in zip(lining[:5], wall_bottom, strict=True):
        assert w[i] == w[j] == pytest.approx(0.5 * height(i)), (i, j, w[i], w[j])  # one weight per position
    row = np.repeat(np.arange(5), 5)  # each patch vertex's row: 0 at the wall's top and at the lining's seam
    into_lining = row * np.hypot(0.7, 0.1) / 4
    np.testing.assert_allclose(
        w[lining], height(lining) * (0.5 + 0.5 * np.clip(into_lining / SEAM_RAMP, 0, 1)), atol=1e-9
    )
    up_the_wall = (4 - row) * np.hypot(0.1, 0.2) / 4
    np.testing.assert_allclose(
        w[wall_index], height(wall_index) * (0.5 - 0.5 * np.clip(up_the_wall / SEAM_RAMP, 0, 1)), atol=1e-9
    )
    assert (w[lining] == 1).any() and (w[wall_index[5:15]] > 0).all()  # both ramps are there
    assert not np.delete(w[: len(face)], wall_index[[0, 2, 4]]).any()  # the sheet lies beyond the wall's ramp
    np.testing.assert_allclose(w[apart], height(apart), atol=1e-12)
    assert (w[apart] > 0.5).any()
    # Positions held still (the upper lip's contact row, the mouth line) take 0 on every copy, the rest as before.
    held = [wall_bottom[2], wall_index[7]]
    still_w = inner_mouth_weights(v, t, None, lm, np.eye(3), 1.0, still=np.array(held))
    zero = [*held, lining[2]]
    assert w[zero].min() > 0 and not still_w[zero].any(), (w[zero], still_w[zero])
    np.testing.assert_array_equal(np.delete(still_w, zero), np.delete(w, zero))


@pytest.mark.system
def test_jaw_weights_mix_a_vertexs_own_motion_with_the_jaws(builtin_rig, builtin_head):
    """On the built-in rig: a moving vertex weighted 0.4 moves by 0.6 of its old displacement plus 0.4 of
    the chin's, a still vertex weighted 1 by the chin's (it joins the moving set), every other vertex as
    before (displacements taken from the old and new rigs' own ``deformed``)."""
    rig, _ = builtin_rig
    chin = int(builtin_head.landmarks["chin"])
    p = np.array([0.01, 0.02, 0.35, -0.03])
    old = rig.deformed(p).astype(np.float64) - rig.neutral
    moved = np.flatnonzero(np.linalg.norm(old, axis=1) > 1e-3 * rig.meta["iod"])
    mixed = int(moved[np.argmax(np.linalg.norm(rig.neutral[moved] - rig.neutral[chin], axis=1))])
    still = int(np.setdiff1d(np.arange(len(rig.neutral)), rig.moving)[0])
    w = np.zeros(len(rig.neutral))
    w[mixed], w[still] = 0.4, 1.0
    new = with_jaw_weights(rig, w, chin)
    got = new.deformed(p).astype(np.float64) - new.neutral
    np.testing.assert_allclose(got[mixed], 0.6 * old[mixed] + 0.4 * old[chin], atol=1e-6)
    np.testing.assert_allclose(got[still], old[chin], atol=1e-6)
    assert np.linalg.norm(old[chin]) > 0.05 * rig.meta["iod"]  # the check above means something
    rest = np.setdiff1d(np.arange(len(rig.neutral)), [mixed, still])
    np.testing.assert_allclose(got[rest], old[rest], atol=1e-6)
    assert new.meta["inner_mouth_pieces"] == 2 and still in new.moving


def test_a_head_split_into_meshes_weighs_each_seam_position_once_and_its_seams_are_found():
    """The face sheet of the first test exported as two meshes, "Head" and "Jaw", and its inner-mouth piece cut
    between them at y = -0.3 (the Jaw's copies of the cut row at the same positions), with lower teeth (another part)
    touching the Jaw at one position. Weighed on the face's part alone, the Jaw's half of the piece took 0 while the
    Head's copies of the cut took the height's weight, and the seam opened with the jaw (issue 12: 4.9 mm on Lee
    Perry-Smith with its jaw as a separate mesh). The Jaw is skin (it meets the Head): each half of the piece is
    weighted by its height, both copies of the cut alike. The teeth stay their own part: unweighted, not skin, no seam.
    """
    from assets.heads.parts import part_seam_pairs, skin_parts
    from realtime_core.face.welding import weld

    xs, ys = np.meshgrid(np.linspace(-2, 2, 21), np.linspace(-2, 2, 21))
    face = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    ft = _patch(-2, 2, -2, 2, 0, 0, n=21)[1]
    hv, ht = _patch(-0.3, 0.3, -0.3, 0.3, -0.25, -0.3)  # the piece's upper half: its first row at y = -0.3
    jv, jt = _patch(-0.3, 0.3, -0.8, -0.3, -0.2, -0.25)  # the lower half: its last row the cut's copies
    jv[-5:] = hv[:5]
    tv, tt = _patch(0.3, 0.5, -0.3, -0.6, -0.25, -0.25)  # teeth: their first corner on the cut's end
    n_f, n_h, n_j = len(face), len(hv), len(jv)
    v = np.vstack([face, hv, jv, tv])
    t = np.vstack([ft, ht + n_f, jt + n_f + n_h, tt + n_f + n_h + n_j])
    head, jaw = np.arange(n_f, n_f + n_h), np.arange(n_f + n_h, n_f + n_h + n_j)
    teeth = np.arange(n_f + n_h + n_j, len(v))
    # The Jaw mesh: the face sheet's lower rows too, whose top row copies the Head's row y = -1 (its own vertices).
    low = np.flatnonzero(face[:, 1] < -1.0 - 1e-9)
    row = np.flatnonzero(np.abs(face[:, 1] + 1.0) < 1e-9)
    part = np.zeros(len(v), dtype=np.int64)
    part[jaw] = 1
    part[teeth] = 2
    part[low] = 1
    copies = len(v) + np.arange(len(row))
    v = np.vstack([v, face[row]])
    part = np.r_[part, np.ones(len(row), dtype=np.int64)]
    remap = np.arange(len(v))
    remap[row] = copies  # the Jaw's faces use its own copies of the row
    below = np.zeros(len(t), dtype=bool)
    below[: len(ft)] = face[ft, 1].mean(axis=1) < -1.0
    t[below] = remap[t[below]]
    names = ("Head", "Jaw", "lower teeth")
    np.testing.assert_array_equal(v[jaw[-5:]], v[head[:5]])
    np.testing.assert_array_equal(v[teeth[0]], v[head[4]])

    def near(p):
        return int(np.argmin(np.linalg.norm(face - p, axis=1)))

    lm = {"corner_left": near([0.5, 0, 0]), "corner_right": near([-0.5, 0, 0]), "chin": near([0, -1, 0])}
    lm["nose_tip"] = near([0, 0.6, 0])
    canon, _ = weld(v)
    np.testing.assert_array_equal(skin_parts(canon, part, 0, names), [0, 1])
    np.testing.assert_array_equal(skin_parts(canon, part, 0, ("Head", "Jaw", "teeth_jaw")), [0, 1])
    np.testing.assert_array_equal(skin_parts(canon, part, 0, ("Head", "Jaw", "chin")), [0, 1, 2])  # named as skin
    w = inner_mouth_weights(v, t, part, lm, np.eye(3), 1.0, part_names=names)

    def height(i):
        return np.clip(-v[i, 1] / JAW_FULL, 0, 1)

    np.testing.assert_array_equal(w[jaw[-5:]], w[head[:5]])  # one weight per position
    np.testing.assert_allclose(w[jaw], height(jaw), atol=1e-12)
    np.testing.assert_allclose(w[head], height(head), atol=1e-12)
    assert (w[jaw] > 0.5).all() and not w[teeth].any() and not w[:n_f].any() and not w[copies].any()
    # The seams between the meshes: the cut's row and the face's row y = -1, each Jaw copy with the Head's vertex.
    pairs = part_seam_pairs(v, part, 0, names)
    want = np.r_[np.c_[head[:5], jaw[-5:]], np.c_[row, copies]]
    np.testing.assert_array_equal(pairs[np.lexsort(pairs.T[::-1])], want[np.lexsort(want.T[::-1])])
    # Positions given to skip (a cut lip seam's) are no seam.
    np.testing.assert_array_equal(part_seam_pairs(v, part, 0, names, skip=np.r_[jaw[-5:], copies]), np.zeros((0, 2)))
