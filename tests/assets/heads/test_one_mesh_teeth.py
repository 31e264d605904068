"""The unnamed teeth rows and tongue of a head exported as one mesh, or as separate parts with generic names (rows
joined in one shell too), move rigidly with the skull or the jaw, unnamed separate eyes with the skull
(:func:`assets.heads.parts.rigid_inner_pieces`, :func:`assets.heads.parts.with_rigid_parts`)."""

from __future__ import annotations

import numpy as np
import pytest

from assets.heads.parts import TEETH_FOLLOW, rigid_inner_pieces
from tests.grids import patch as _patch
from tests.grids import stacked


def _mouth_and_pieces():
    """The face sheet and the pieces behind it of the first test below: vertices, triangles, landmarks, piece name ->
    its vertex indices (the face sheet's: "face")."""
    xs, ys = np.meshgrid(np.linspace(-2, 2, 21), np.linspace(-2, 2, 21))
    face = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    ft = _patch(-2, 2, -2, 2, 0, 0, n=21)[1]

    def near(p):
        return int(np.argmin(np.linalg.norm(face[:, :2] - p, axis=1)))

    lm = {"corner_left": near([0.5, 0]), "corner_right": near([-0.5, 0]), "chin": near([0, -1])}
    lm |= {"nose_tip": near([0, 0.6])}
    lm |= {"upper_lip": near([0, 0.2]), "lower_lip": near([0, -0.2])}
    lm |= {k: near([x, 1.0]) for k, x in (("eye_outer_left", 1), ("eye_inner_left", 0.4))}
    lm |= {k: near([x, 1.0]) for k, x in (("eye_outer_right", -1), ("eye_inner_right", -0.4))}
    face[lm["upper_lip"], 2], face[lm["lower_lip"], 2] = 0.3, 0.25
    pieces = {
        "upper": _patch(-0.5, 0.5, 0.05, 0.3, -0.2, -0.4),
        "lower": _patch(-0.5, 0.5, -0.3, -0.05, -0.2, -0.4),
        "tongue": _patch(-0.2, 0.2, -0.15, -0.05, -0.3, -1.0),
        "lining": _patch(-0.3, 0.3, -0.8, 0.3, -0.3, -0.2),
        "seamed": _patch(-0.4, 0.4, 0.0, 0.2, 0.0, -0.3),  # its first row at face positions (y = 0, z = 0)
        "front": _patch(-0.3, 0.3, -0.6, 0.0, -0.2, 0.4),
        "eye": _patch(0.3, 0.7, 0.9, 1.1, -0.1, -0.1),
    }
    v, t, at = stacked(face, ft, pieces)
    at["face"] = np.arange(len(face))
    seamed_top = at["seamed"][:5]
    v[seamed_top] = face[[near(p) for p in v[seamed_top, :2]]]  # copies of the face's positions, to the bit
    assert np.abs(v[seamed_top] - np.c_[np.linspace(-0.4, 0.4, 5), np.zeros((5, 2))]).max() < 1e-12
    return v, t, lm, at


def test_only_low_wide_shells_behind_the_lips_are_rigid_upper_row_with_the_skull_lower_row_and_tongue_with_the_jaw():
    """A face sheet (z = 0, lips bulging to z = 0.3 and 0.25, mouth corners at (+-0.5, 0), chin at y = -1, eyes at
    y = 1; IOD 1) and separate pieces behind it: an upper and a lower teeth row (low wide arches either side of the
    mouth line), a tongue (deeper than wide, its middle just below the line), a lining of the mouth's inside (taller
    than wide, from y = 0.3 down to -0.8), a row whose top edge shares the face's positions (a piece only across texture
    seams), a piece poking in front of the lips and an eyeball. Only the rows and the tongue are rigid pieces: the upper
    row "skull", the lower row and the tongue "jaw", every other vertex ""."""
    v, t, lm, at = _mouth_and_pieces()
    n = len(v)
    seamed_top = at["seamed"][:5]
    labels = rigid_inner_pieces(v, t, None, lm, np.eye(3), 1.0)
    assert (labels[at["upper"]] == "skull").all()
    assert (labels[at["lower"]] == "jaw").all() and (labels[at["tongue"]] == "jaw").all()
    rest = np.setdiff1d(np.arange(n), np.r_[at["upper"], at["lower"], at["tongue"]])
    assert (labels[rest] == "").all()
    # The seamed row is a rigid row once its seam is apart (moved off the face's positions): the weld decided it.
    v2 = v.copy()
    v2[seamed_top, 2] -= 0.01
    assert (rigid_inner_pieces(v2, t, None, lm, np.eye(3), 1.0)[at["seamed"]] == "skull").all()


@pytest.mark.system
def test_a_builtin_like_head_as_one_mesh_keeps_its_upper_teeth_still_and_moves_its_lower_teeth_and_tongue_rigidly(
    builtin_head,
):
    """The built-in head's mesh exported as one mesh (no parts, another name) with its landmarks, rigged: at /a/ the
    upper teeth row (the head's part 2) does not move; the lower row (part 3) and the tongue (part 4) move by one
    displacement, whose drop along the face's up axis is TEETH_FOLLOW of the lower inner lip's (measured on the rig's
    own deformed vertices), and the head's figures say which vertices were found."""
    from dataclasses import replace

    from assets.heads.rigging import mouth_landmarks, rig_head
    from realtime_core.face import face_frame

    mesh = replace(builtin_head.mesh, name="one mesh")
    rig, _ = rig_head(mesh, dict(builtin_head.landmarks), head=builtin_head)
    part = np.asarray(builtin_head.part)
    n = len(part)
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    d = np.asarray(rig.deformed(np.array([0.0, 0.02, 0.35, 0.0])), dtype=np.float64) - v0
    lm = {k: int(np.argmin(np.linalg.norm(v0 - np.asarray(p), axis=1))) for k, p in rig.meta["landmarks"].items()}
    frame = face_frame(v0, mouth_landmarks(lm))
    iod = frame.iod
    upper, lower, tongue = (np.flatnonzero(part == i) for i in (2, 3, 4))
    assert np.abs(d[:n][upper]).max() == 0.0
    jaw = d[:n][np.r_[lower, tongue]]
    np.testing.assert_allclose(jaw, np.broadcast_to(jaw[0], jaw.shape), atol=1e-6 * iod)  # one rigid displacement
    lip_drop = float(d[lm["lower_inner"]] @ frame.axes[1])
    assert lip_drop < -0.2 * iod  # the mouth opens: the check below means something
    np.testing.assert_allclose(float(jaw[0] @ frame.axes[1]), TEETH_FOLLOW * lip_drop, rtol=1e-4)
    assert sorted(rig.meta["inner_rigid_pieces"]) == sorted(np.r_[upper, lower, tongue].tolist())


def test_unnamed_separate_parts_are_judged_by_shape_as_a_one_mesh_heads_shells_are_and_an_unnamed_eye_is_rigid():
    """The same face and pieces, each piece a separate part named generically ("Object002"...): the rows and the tongue
    are found as on the one-mesh head (a part touching the face nowhere is no skin, but no less a teeth row), the eye
    piece (within the eye's width of its corners' midpoint) is "eye"; the lining, the piece in front of the lips and
    the seamed row (its part shares the face's positions: skin) are not. Parts whose names say what they are (teeth
    rows, an "Eye_L") are :func:`rigid_labels`' to move, not this function's."""
    v, t, lm, at = _mouth_and_pieces()
    part = np.zeros(len(v), dtype=np.int64)
    order = [k for k in at if k != "face"]
    for i, k in enumerate(order, start=1):
        part[at[k]] = i
    names = tuple(f"Object{i + 1:03d}" for i in range(len(order) + 1))
    labels = rigid_inner_pieces(v, t, part, lm, np.eye(3), 1.0, part_names=names)
    expect = {"upper": "skull", "lower": "jaw", "tongue": "jaw", "eye": "eye"}
    for k in at:
        assert (labels[at[k]] == expect.get(k, "")).all(), k
    said = dict(zip(order, names[1:])) | {"upper": "teeth_upper", "lower": "teeth_lower", "eye": "Eye_L"}
    labels = rigid_inner_pieces(v, t, part, lm, np.eye(3), 1.0, part_names=("head", *said.values()))
    assert (labels[np.r_[at["upper"], at["lower"], at["eye"]]] == "").all()
    assert (labels[at["tongue"]] == "jaw").all()


def _rows_joined(triangles: np.ndarray, vertices: np.ndarray, upper: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """(4, 3) triangles joining the teeth rows ``upper`` and ``lower`` (vertex indices) into one shell: two each side
    (x > 0, x < 0), at the rows' closest vertices and one neighbour of each along its row."""
    out = []
    for s in (1.0, -1.0):
        u, lo = upper[vertices[upper, 0] * s > 0], lower[vertices[lower, 0] * s > 0]
        d = np.linalg.norm(vertices[u][:, None] - vertices[lo][None], axis=2)
        i, j = np.unravel_index(np.argmin(d), d.shape)
        a, c = int(u[i]), int(lo[j])
        a2 = next(int(x) for x in triangles[(triangles == a).any(axis=1)].ravel() if x != a and x in upper)
        c2 = next(int(x) for x in triangles[(triangles == c).any(axis=1)].ravel() if x != c and x in lower)
        out += [[a, c, a2], [a2, c, c2]]
    return np.asarray(out, dtype=np.int64)


@pytest.mark.system
def test_the_builtin_head_with_generic_part_names_and_its_rows_joined_moves_as_with_its_parts_named(builtin_head):
    """The built-in head's mesh as a studio may export it: its parts named "Object001".."Object004" (skin, eyes, both
    teeth rows in one part, tongue) and the two rows joined into one shell by two triangles each side. Rigged, at /a/
    every vertex moves as on the same head with its parts named (skin, eyes, upper_teeth, lower_teeth, tongue): the
    upper row and the eyes still, the lower row and the tongue one displacement whose drop along the face's up axis is
    TEETH_FOLLOW of the lower inner lip's. The joining triangles stretch (the rows part) but are teeth: the checks count
    no flip or stretch on them."""
    from dataclasses import replace

    from assets.heads.rigging import mouth_landmarks, rig_head
    from realtime_core.face import face_frame
    from realtime_core.face.checks import pose_figures

    base = builtin_head.mesh
    part = np.asarray(builtin_head.part, dtype=np.int64)
    upper, lower, tongue, eyes = (np.flatnonzero(part == i) for i in (2, 3, 4, 1))
    t = np.asarray(base.triangles, dtype=np.int64)
    joined = np.vstack([t, _rows_joined(t, np.asarray(base.vertices, dtype=np.float64), upper, lower)])
    named = replace(base, name="named", part=part, part_names=("skin", "eyes", "upper_teeth", "lower_teeth", "tongue"))
    generic = replace(
        base,
        name="generic",
        triangles=joined,
        part=np.where(part >= 3, part - 1, part),
        part_names=("Object001", "Object002", "Object003", "Object004"),
    )
    lm = dict(builtin_head.landmarks)
    pose = np.array([0.0, 0.02, 0.35, 0.0])
    rig_named, _ = rig_head(named, lm, head=builtin_head)
    rig, _ = rig_head(generic, lm, head=builtin_head)
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    frame = face_frame(v0, mouth_landmarks(lm))
    d = np.asarray(rig.deformed(pose), dtype=np.float64) - v0
    d_named = np.asarray(rig_named.deformed(pose), dtype=np.float64) - np.asarray(rig_named.neutral, dtype=np.float64)
    np.testing.assert_allclose(d, d_named, atol=1e-6 * frame.iod)
    assert np.abs(d[np.r_[upper, eyes]]).max() == 0.0
    jaw = d[np.r_[lower, tongue]]
    np.testing.assert_allclose(jaw, np.broadcast_to(jaw[0], jaw.shape), atol=1e-6 * frame.iod)
    lip_drop = float(d[lm["lower_inner"]] @ frame.axes[1])
    assert lip_drop < -0.2 * frame.iod
    np.testing.assert_allclose(float(jaw[0] @ frame.axes[1]), TEETH_FOLLOW * lip_drop, rtol=1e-4)
    assert sorted(rig.meta["inner_rigid_pieces"]) == sorted(np.r_[upper, lower, tongue].tolist())
    assert rig.meta["eye_rigid_pieces"] == len(eyes)
    teeth = np.r_[upper, lower, tongue]
    with_teeth = pose_figures(rig, mouth_landmarks(lm), pose[None], teeth=teeth)
    assert with_teeth.flipped[0] == 0
    assert with_teeth.stretch[0] == pose_figures(rig_named, mouth_landmarks(lm), pose[None], teeth=teeth).stretch[0]
    assert pose_figures(rig, mouth_landmarks(lm), pose[None]).stretch[0] > 10.0  # the joining triangles, counted
