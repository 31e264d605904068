"""The inside shown through the skin (realtime_core.face.checks.inside_shown) and the lining kept behind it
(assets.heads.lining): a wall pushed through a cheek is flagged and moved back; the built-in head passes untouched."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from realtime_core.face.checks import (
    EXTREME_POSES,
    INSIDE_SHOWN_LIMIT,
    RigCheckLimits,
    check_rig,
    inside_poses,
    inside_shown,
)
from realtime_core.face.model import FaceModel, MouthCalibration, MouthLandmarks
from realtime_core.face.rig import Rig

WALL_DEPTH = 0.05
"""IOD: how far the wall lies behind the cheek at rest (the thin old woman's bag walls: 0.07-0.08)."""
PUSH = 0.2
"""IOD of forward motion per unit mouth_open of the wall (at mouth_open 0.465: 0.093, through the cheek by 0.043)."""


def _grid(x: np.ndarray, y: np.ndarray, z: float) -> tuple[np.ndarray, np.ndarray]:
    """A flat sheet at depth z: its vertices (len(x) * len(y), 3) and triangles."""
    xx, yy = np.meshgrid(x, y)
    v = np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)])
    nx = len(x)
    t = []
    for r in range(len(y) - 1):
        for c in range(nx - 1):
            a = r * nx + c
            t += [[a, a + 1, a + nx + 1], [a, a + nx + 1, a + nx]]
    return v, np.array(t)


def _cheek_and_wall(push: float = PUSH) -> tuple[Rig, MouthLandmarks, np.ndarray, np.ndarray]:
    """A flat face (z = 0, IOD 1, mouth corners at x = +-0.3 on y = 0, eyes at y = 1) and a wall WALL_DEPTH behind
    its left cheek (x 0.4-0.7, y 0-0.3): the skin never moves, the wall moves forward by ``push`` per unit
    mouth_open. Returns (rig, landmarks, skin vertices, wall vertices)."""
    skin, ts = _grid(np.linspace(-0.8, 0.8, 33), np.linspace(-0.6, 0.6, 25), 0.0)
    wall, tw = _grid(np.linspace(0.4, 0.7, 7), np.linspace(0.0, 0.3, 7), -WALL_DEPTH)
    eyes = np.array([[0.6, 1.0, 0.0], [0.4, 1.0, 0.0], [-0.4, 1.0, 0.0], [-0.6, 1.0, 0.0]])
    v = np.vstack([skin, wall, eyes])
    t = np.vstack([ts, tw + len(skin)])
    skin_i, wall_i = np.arange(len(skin)), len(skin) + np.arange(len(wall))

    def at(x: float, y: float) -> int:
        return int(np.argmin(np.linalg.norm(skin[:, :2] - [x, y], axis=1)))

    e = len(skin) + len(wall)
    lm = MouthLandmarks(
        eye_outer_left=e,
        eye_inner_left=e + 1,
        eye_inner_right=e + 2,
        eye_outer_right=e + 3,
        corner_left=at(0.3, 0.0),
        corner_right=at(-0.3, 0.0),
        upper_lip=at(0.0, 0.1),
        lower_lip=at(0.0, -0.1),
        upper_inner=at(0.0, 0.0),
        lower_inner=at(0.0, 0.0),
    )
    # One simple vertex whose displacement is (0, 0, push) per unit mouth_open; every moving vertex's rows pick it
    # (the wall's) or nothing (the skin's).
    moving = np.arange(len(v) - 4)
    basis = np.zeros((3, 4))
    basis[2, 2] = push
    rows = 3 * np.searchsorted(moving, wall_i) + 2
    matrix = sp.csr_matrix((np.ones(len(rows)), (rows, np.full(len(rows), 2))), shape=(3 * len(moving), 3))
    rig = Rig(
        neutral=v.astype(np.float32),
        triangles=t.astype(np.int32),
        moving=moving,
        matrix=matrix,
        basis=basis,
        control=np.zeros(1, dtype=np.int64),
        simple=FaceModel(vertices=np.zeros((1, 3)), triangles=np.zeros((0, 3), int)),
        calibration=MouthCalibration(groups=(("a",), ("b",), ("c",), ("d",)), response=np.eye(4), matrix=np.eye(4)),
    )
    return rig, lm, skin_i, wall_i


def test_a_wall_pushed_through_the_cheek_is_flagged_by_how_far_it_comes_through() -> None:
    rig, lm, _, _ = _cheek_and_wall()
    poses = inside_poses(EXTREME_POSES)
    widest = max(p[2] for p in poses)
    got = inside_shown(rig, lm, poses=poses)
    assert got is not None
    # Independent: the flat wall lies PUSH * mouth_open - WALL_DEPTH in front of the flat skin at the widest opening;
    # along a three-quarter view's rays (35 degrees off the planes' normal) that gap is 1 / cos 35 as long.
    assert got[0] == pytest.approx((PUSH * widest - WALL_DEPTH) / np.cos(np.radians(35.0)), abs=1e-6)
    assert got[1] > 0 and got[2][2] == widest
    report = check_rig(rig, lm, poses=poses, expression_poses=())
    assert not report.passed and any("behind the skin" in f for f in report.failures)
    assert report.inside_shown_iod == pytest.approx(got[0])
    # Not pushed so far, it stays behind the skin and is not counted: 0.1 * 0.465 < 0.05.
    behind, _, _, _ = _cheek_and_wall(push=0.1)
    assert inside_shown(behind, lm, poses=poses) == (0.0, 0, ())
    assert check_rig(behind, lm, poses=poses, expression_poses=()).inside_shown_iod == 0.0
    assert RigCheckLimits().max_inside_shown == INSIDE_SHOWN_LIMIT


def test_the_lining_moves_the_wall_with_the_cheek_and_leaves_the_skin_as_it_was() -> None:
    from assets.heads.lining import with_lining_behind_skin

    rig, lm, skin, wall = _cheek_and_wall()
    lined = with_lining_behind_skin(rig, lm)
    assert lined is not None and lined.meta["inside_lined"] == len(wall)
    for pose in EXTREME_POSES:
        p = np.asarray(pose)
        before, after = rig.deformed(p), lined.deformed(p)
        np.testing.assert_array_equal(after[skin], before[skin])
        # The whole wall came through, so all of it takes the (still) skin's motion: it stays where it was.
        np.testing.assert_allclose(after[wall], rig.neutral[wall], atol=1e-7)
    assert inside_shown(lined, lm, poses=EXTREME_POSES) == (0.0, 0, ())
    # Nothing comes through: nothing to line.
    behind, _, _, _ = _cheek_and_wall(push=0.1)
    assert with_lining_behind_skin(behind, lm) is None


def test_the_built_in_head_shows_nothing_through_its_skin_and_is_not_lined(builtin_rig_file) -> None:
    from assets.heads.head import Head, head_check_inputs
    from assets.heads.lining import with_lining_behind_skin

    rig, mesh = builtin_rig_file
    lm, _ = head_check_inputs(Head(rig, mesh))
    got = inside_shown(rig, lm, poses=EXTREME_POSES)
    assert got is not None and got[0] <= INSIDE_SHOWN_LIMIT
    assert with_lining_behind_skin(rig, lm) is None
