"""The unnamed teeth rows and tongue of a head exported as one mesh move rigidly with the skull or the jaw
(:func:`assets.heads.parts.rigid_inner_pieces`, :func:`assets.heads.parts.with_rigid_parts`)."""

from __future__ import annotations

import numpy as np
import pytest

from assets.heads.parts import TEETH_FOLLOW, rigid_inner_pieces
from tests.grids import patch as _patch


def test_only_low_wide_shells_behind_the_lips_are_rigid_upper_row_with_the_skull_lower_row_and_tongue_with_the_jaw():
    """A face sheet (z = 0, lips bulging to z = 0.3 and 0.25, mouth corners at (+-0.5, 0), chin at y = -1, eyes at
    y = 1; IOD 1) and separate pieces behind it: an upper and a lower teeth row (low wide arches either side of the
    mouth line), a tongue (deeper than wide, its middle just below the line), a lining of the mouth's inside (taller
    than wide, from y = 0.3 down to -0.8), a row whose top edge shares the face's positions (a piece only across texture
    seams), a piece poking in front of the lips and an eyeball. Only the rows and the tongue are rigid pieces: the upper
    row "skull", the lower row and the tongue "jaw", every other vertex ""."""
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
    v, t, at = [face], [ft], {}
    n = len(face)
    for name, (pv, pt) in pieces.items():
        at[name] = np.arange(n, n + len(pv))
        v.append(pv)
        t.append(pt + n)
        n += len(pv)
    v, t = np.vstack(v), np.vstack(t)
    seamed_top = at["seamed"][:5]
    v[seamed_top] = face[[near(p) for p in v[seamed_top, :2]]]  # copies of the face's positions, to the bit
    assert np.abs(v[seamed_top] - np.c_[np.linspace(-0.4, 0.4, 5), np.zeros((5, 2))]).max() < 1e-12

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
