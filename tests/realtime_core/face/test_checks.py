"""The rig checks' pose set and what the checks catch."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from realtime_core.errors import ConfigError
from realtime_core.face.checks import (
    CHECK_POSES,
    CLOSURE_REACH,
    EXPRESSION_POSES,
    EXTREME_POSES,
    MEASURED_POSES,
    SINGLE_POSES,
    SLIVER_REST,
    SPEECH_POSES,
    SPEECH_SCALE,
    PoseBound,
    RigCheckLimits,
    check_rig,
    checked_bound,
    flipped_faces,
    pose_figures,
)
from realtime_core.face.model import MouthLandmarks
from tests.grids import grid_triangles
from training.articulatory import CLASSES


def test_speech_poses_are_the_articulatory_targets_scaled() -> None:
    # The table in checks.py (realtime_core cannot import training) must follow the classes.
    want = sorted(
        tuple(round(float(x) * SPEECH_SCALE, 3) + 0.0 for x in c.target) for c in CLASSES.values() if not c.silence
    )
    assert sorted(SPEECH_POSES) == want
    assert np.isclose(np.array(SPEECH_POSES)[:, 2].max(), 0.45)


def test_single_poses_reach_the_ends_of_every_other_pose() -> None:
    span = np.array(SPEECH_POSES + MEASURED_POSES)
    lo, hi = span.min(0), span.max(0)
    singles = np.array(SINGLE_POSES)
    # Each single pose moves one parameter to an end of the span, both ends of each (mouth_open: 0 is rest).
    assert np.all((singles != 0).sum(1) == 1)
    for j in range(4):
        ends = singles[:, j][singles[:, j] != 0]
        assert ends.max() >= hi[j] - 1e-9
        assert lo[j] == 0 or ends.min() <= lo[j] + 1e-9


# The box the checks tested before they were measured on the shipped models (the articulatory
# targets' span): the frames below lie outside it.
ARTICULATORY_BOX = ((-0.014, 0.034), (-0.123, 0.089), (0.0, 0.45), (-0.027, 0.034))


@pytest.mark.parametrize("model_name", ["default", "low-latency"])
def test_checked_poses_hold_every_frame_a_shipped_model_produces(shared_data: Path, model_name: str) -> None:
    # Real speech of a voice no model was trained on, through the live path: every frame lies in the
    # convex hull of the checked poses (within the 0.002 IOD the table was chosen to), so a rig that
    # passes the checks is checked where this speech takes it (scripts/measure_param_box.py).
    from scipy.spatial import ConvexHull

    from assets.audio import read_audio
    from assets.modelfile import load_speech_model
    from realtime_core.pipeline import speech_to_params

    samples, rate = read_audio(shared_data / "speech" / "praatio" / "bobby.wav")
    x = np.asarray(speech_to_params(load_speech_model("hmm", model_name), samples, rate), dtype=np.float64)[:, :4]
    x[:, 2] = np.maximum(x[:, 2], 0.0)
    lo, hi = np.array(ARTICULATORY_BOX).T
    assert np.any((x < lo - 0.01) | (x > hi + 0.01)), "the speech no longer leaves the old box: pick another file"
    eq = ConvexHull(np.array(EXTREME_POSES)).equations
    outside = (x @ eq[:, :4].T + eq[:, 4]).max(axis=1)
    assert outside.max() <= 0.002 + 1e-6, x[int(np.argmax(outside))]


def test_the_generated_expression_poses_are_a_fresh_computation() -> None:
    # EXPRESSION_POSES is a table `facecast fit-maps` writes into realtime_core/fitted_maps.py (computing it took
    # 0.2-0.8 s of every import of the checks): it must be what the pruning gives for today's speech poses and
    # expression table, or the checks and the bound hold a stale set.
    from facecast.commands.fit_maps import REGENERATE
    from realtime_core.face.checks import expression_poses
    from realtime_core.fitted_maps import EXPRESSION_PARAMS

    fresh = expression_poses(EXTREME_POSES, EXPRESSION_PARAMS)
    assert fresh == EXPRESSION_POSES, f"realtime_core/fitted_maps.py is stale: run `{REGENERATE}`"
    assert all(type(x) is float for row in EXPRESSION_POSES for x in row) and len(EXPRESSION_POSES) > 0


def test_importing_the_checks_builds_no_hull() -> None:
    # A fresh interpreter counting Qhull's hulls while the checks are imported: the pose set was pruned at import
    # (67 poses, a hull per pose added), 0.2-0.8 s of every command with a head and of the server's start.
    import subprocess
    import sys

    code = (
        "import scipy.spatial as s\n"
        "built = []\n"
        "class Counted(s.ConvexHull):\n"
        "    def __init__(self, *a, **k):\n"
        "        built.append(1)\n"
        "        super().__init__(*a, **k)\n"
        "s.ConvexHull = Counted\n"
        "import realtime_core.face.checks\n"
        "print(len(built))\n"
    )
    root = Path(__file__).resolve().parents[3]
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True, cwd=root)
    assert r.stdout.strip() == "0", r.stdout + r.stderr


def test_checked_poses_hold_speech_under_every_expression() -> None:
    # The live path layers an expression on speech by add_expression; speech at any intensity in [0, 1] of one
    # expression lies between a speech pose and its copy at intensity 1. Independently of how EXPRESSION_POSES
    # was pruned: every speech pose and every frame of it under each expression at intensities 0.1..1 lies in
    # the hull of CHECK_POSES (within the 0.002 IOD the set was chosen to, plus its 0.0001 rounding).
    from scipy.spatial import ConvexHull

    from realtime_core.expressions import EXPRESSIONS, add_expression
    from realtime_core.fitted_maps import EXPRESSION_PARAMS

    speech = np.array(EXTREME_POSES)
    eq = ConvexHull(np.array(CHECK_POSES)).equations
    for k, name in enumerate(EXPRESSIONS):
        for a in np.arange(1, 11) / 10:
            x = add_expression(speech, np.tile(a * EXPRESSION_PARAMS[k], (len(speech), 1)))
            outside = (x @ eq[:, :4].T + eq[:, 4]).max(axis=1)
            assert outside.max() <= 0.002 + 1e-6, (name, a, x[int(np.argmax(outside))])
    # Without the expression poses the smile on speech is far outside (the sweep's say set flipped there).
    eq0 = ConvexHull(speech).equations
    smile = add_expression(speech, np.tile(EXPRESSION_PARAMS[EXPRESSIONS.index("smile")], (len(speech), 1)))
    assert (smile @ eq0[:, :4].T + eq0[:, 4]).max() > 0.05
    assert set(EXTREME_POSES) <= set(CHECK_POSES) and len(CHECK_POSES) == len(EXTREME_POSES) + len(EXPRESSION_POSES)
    # The bound a head drives its rig within holds them too: a full smile on speech moves by at most the
    # 0.002 IOD the pose set was pruned to (with EXTREME_POSES alone it was cut back to lip_stretch 0.094).
    moved = np.abs(checked_bound()(smile) - smile).max()
    assert moved <= 0.002 + 1e-6, moved


class _Stretch:
    """The flat grid of _Fold whose centre vertex moves right with lip_stretch: inside its neighbours up to
    lip_stretch 0.1 (past the speech end 0.094 only by a smile), past the right column beyond."""

    def __init__(self) -> None:
        self._grid = _Fold()
        self.neutral, self.triangles = self._grid.neutral, self._grid.triangles

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = self.neutral.copy()
        v[4, 0] += 10.0 * max(float(p[1]), 0.0)
        return v


def test_check_rig_reports_a_fold_only_an_expression_reaches() -> None:
    # Folds at lip_stretch > 0.1: no speech pose reaches it (the widest 0.094), a smile on speech does. The
    # check reports it under expressions (advisory: a warning) and passes the speech poses.
    rep = check_rig(_Stretch(), _fold_landmarks())
    assert rep.flipped_triangles == 0 and not any("flipped" in f for f in rep.failures), rep.failures
    assert rep.expression_flips is not None and rep.expression_flips > 0
    assert rep.expression_flip_pose[1] > 0.1
    assert any("under an expression" in w for w in rep.warnings), rep.warnings
    assert check_rig(_Fold(), _fold_landmarks(), expression_poses=()).expression_flips is None


def test_a_rig_that_folds_at_expression_poses_is_bound_to_those_it_holds() -> None:
    # _Stretch folds where lip_stretch > 0.1 (its centre vertex passes the right column at x = 2): the smiles on
    # speech reach past that, speech alone does not. Its checks list the expression poses it holds, those at
    # lip_stretch <= 0.1 by that geometry, and the bound made of them drives it flip-free at any parameters.
    from realtime_core.expressions import EXPRESSIONS, add_expression
    from realtime_core.fitted_maps import EXPRESSION_PARAMS

    rig, lm = _Stretch(), _fold_landmarks()
    rep = check_rig(rig, lm)
    assert rep.expressions_held is not None
    want = {p for p in EXPRESSION_POSES if p[1] <= 0.1}
    assert set(rep.expressions_held) == want and 0 < len(want) < len(EXPRESSION_POSES)
    bound = checked_bound(rep.expressions_held)
    assert set(bound.poses) == set(EXTREME_POSES) | want | {(0.0, 0.0, -CLOSURE_REACH, 0.0)}
    speech = np.array(EXTREME_POSES)
    smile = add_expression(speech, np.tile(EXPRESSION_PARAMS[EXPRESSIONS.index("smile")], (len(speech), 1)))
    free = pose_figures(rig, lm, smile).flipped
    assert free.max() > 0  # what the bound keeps this rig from
    rng = np.random.default_rng(7)
    far = np.vstack([smile, np.array(CHECK_POSES), rng.normal(size=(200, 4)) * [0.1, 0.25, 0.6, 0.15]])
    held = bound(far)
    assert pose_figures(rig, lm, held).flipped.max() == 0
    assert held[:, 1].max() <= 0.1 + 1e-6
    # Speech is not cut: every speech pose is kept as it is; the full set keeps every checked pose.
    np.testing.assert_array_equal(bound(speech), speech)
    assert set(checked_bound().poses) == set(CHECK_POSES) | {(0.0, 0.0, -CLOSURE_REACH, 0.0)}
    # Kept in a rig's meta as JSON: the same poses after a round trip.
    import json

    again = json.loads(json.dumps(rep.as_dict()))["expressions_held"]
    assert tuple(tuple(p) for p in again) == rep.expressions_held


class _Fold:
    """A flat 2x2 grid of quads whose centre vertex moves through its neighbours with mouth_open."""

    def __init__(self) -> None:
        g = np.array([[x, y, 0.0] for y in range(3) for x in range(3)], dtype=np.float64)
        self.neutral = g
        self.triangles = grid_triangles(3, 3)

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = self.neutral.copy()
        v[4, 0] += 10.0 * p[2]  # 0.45 -> 4.5: far past the right column, folding its triangles
        return v


def _fold_landmarks() -> MouthLandmarks:
    return MouthLandmarks(
        eye_outer_left=2,
        eye_inner_left=5,
        eye_inner_right=3,
        eye_outer_right=0,
        corner_left=8,
        corner_right=6,
        upper_lip=7,
        lower_lip=7,
        upper_inner=7,
        lower_inner=7,
    )


def test_check_catches_a_fold() -> None:
    rep = check_rig(_Fold(), _fold_landmarks())
    assert rep.flipped_triangles > 0 and not rep.passed


class _Band:
    """A flat grid, 3 columns 1 apart, rows at y = 0, 1, 1 + ``height``, 2 + ``height``, 3 + ``height``: the row
    between y = 1 and 1 + height is a band (a sliver when height is small). mouth_open p lifts every row above the
    band by ``lift * p``, so only the band's vertical edges (rest length ``height``) and diagonals stretch."""

    def __init__(self, height: float, lift: float) -> None:
        ys = [0.0, 1.0, 1.0 + height, 2.0 + height, 3.0 + height]
        self.neutral = np.array([[x, y, 0.0] for y in ys for x in range(3)], dtype=np.float64)
        self.triangles = grid_triangles(5, 3)
        self.lift = lift

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = self.neutral.copy()
        v[6:, 1] += self.lift * p[2]
        return v


def test_a_slivers_stretch_is_counted_from_a_fifth_of_the_median_edge() -> None:
    # The widest opening of the checks' poses lifts the rows above the band; the band's vertical edge goes from
    # `height` to height + lift * open. Its rest length is counted as at least SLIVER_REST of the median edge (1
    # here: most edges are the grid's unit edges), so a sliver 0.1 tall stretched 4.5x (to 0.45, under half an
    # edge) passes, reported with a warning; the same band stretched to 1.0 (10x, 5x from 0.2) fails, and an
    # ordinary row stretched 4.5x fails as before.
    widest = max(p[2] for p in EXTREME_POSES)
    lm = _fold_landmarks()

    def report(height: float, to: float):
        rig = _Band(height, (to - height) / widest)
        per = pose_figures(rig, lm, EXTREME_POSES)
        # (The lips are one vertex here, so they never part: the opening's limit is off; and the grid's faces turn
        # their backs to the face frame's forward view, drawn dark where lips would meet: that limit is off too.)
        return per, check_rig(rig, lm, limits=RigCheckLimits(min_open_response=0.0, max_lips_dark=np.inf))

    assert SLIVER_REST == 0.2
    per, rep = report(0.1, 0.45)
    assert np.isclose(per.stretch.max(), 4.5) and np.isclose(rep.max_edge_stretch, 4.5)
    assert np.isclose(rep.sliver_stretch, 0.45 / 0.2)
    assert rep.passed and rep.flipped_triangles == 0
    assert any("sliver" in w for w in rep.warnings)
    _, rep = report(0.1, 1.0)
    assert np.isclose(rep.max_edge_stretch, 10.0) and np.isclose(rep.sliver_stretch, 5.0)
    assert not rep.passed and any("edge stretch" in f for f in rep.failures)
    _, rep = report(1.0, 4.5)
    assert np.isclose(rep.max_edge_stretch, 4.5) and np.isclose(rep.sliver_stretch, 4.5)
    assert not rep.passed and not any("sliver" in w for w in rep.warnings)


def test_pose_figures_finds_the_fold_at_the_poses_that_make_it_and_its_faces() -> None:
    # The centre vertex at x = 1 + 10 mouth_open: inside its neighbours up to mouth_open 0.1, past the right
    # column (x = 2) beyond it. A triangle is flipped where its signed area in the plane changes sign; the
    # longest edge is (3, 4), rest length 1, from x = 0 to x = 1 + 10 mouth_open.
    rig = _Fold()
    opens = np.array([0.0, 0.05, 0.09, 0.2, 0.45])
    poses = np.column_stack([np.zeros((5, 2)), opens, np.zeros(5)])
    per = pose_figures(rig, _fold_landmarks(), poses)
    t = rig.triangles

    def area(v: np.ndarray) -> np.ndarray:
        a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
        return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])

    for i, p in enumerate(poses):
        v = rig.deformed(p)
        want = np.flatnonzero(np.sign(area(v)) != np.sign(area(rig.neutral)))
        assert list(flipped_faces(v, rig.neutral, t, 1.0)) == list(want)
        assert per.flipped[i] == len(want)
    assert list(per.flipped[:3]) == [0, 0, 0] and per.flipped[3] > 0
    assert np.allclose(per.stretch[1:], 1 + 10 * opens[1:])
    assert per.teeth_ahead is None
    # check_rig reports the worst of these (its closure pose is the rest pose here: the lips are one vertex).
    rep = check_rig(rig, _fold_landmarks(), poses=tuple(map(tuple, poses)))
    assert rep.flipped_triangles == per.flipped.max() and np.isclose(rep.max_edge_stretch, per.stretch.max())
    assert rep.worst_flip_pose == tuple(poses[int(np.argmax(per.flipped))])


class _Lips:
    """Two lip strips meeting on a cut from corner (x = -0.3) to corner (x = 0.3), IOD 1 (eye centres at
    x = +-0.5, y = 1, not part of any triangle). ``zigzag``: the cut's interior vertices alternate
    ``zigzag`` above and below the corner line (a cut through zig-zagging landmark points); else it is
    straight. mouth_open p drops the lower strip by ``p * (1 - (x / 0.3)**2)``: a smooth opening."""

    COLS = 25  # 0.025 IOD apart

    def __init__(self, zigzag: float) -> None:
        x = np.linspace(-0.3, 0.3, self.COLS)
        cut = np.where(np.arange(self.COLS) % 2 == 1, zigzag, -zigzag)
        cut[[0, -1]] = 0.0
        self.x, self.cut = x, cut
        rows = []
        # Upper strip: the cut and two rows above it; lower strip: its own copy of the cut and two rows below.
        for dy in (0.0, 0.1, 0.2):
            rows.append(np.column_stack([x, cut + dy, np.zeros_like(x)]))
        for dy in (0.0, -0.1, -0.2):
            rows.append(np.column_stack([x, cut + dy, np.zeros_like(x)]))
        eyes = np.array([[0.6, 1.0, 0.0], [0.4, 1.0, 0.0], [-0.4, 1.0, 0.0], [-0.6, 1.0, 0.0]])
        self.neutral = np.vstack([*rows, eyes])
        n = self.COLS
        t = []
        for strip in (0, 3):
            for r in range(2):
                for c in range(n - 1):
                    a = (strip + r) * n + c
                    b = a + n
                    # Same winding for both strips as seen from +z.
                    t += [[a, a + 1, b + 1], [a, b + 1, b]] if strip == 0 else [[a, b + 1, a + 1], [a, b, b + 1]]
        self.triangles = np.array(t)
        self.lower = np.arange(3 * n, 6 * n)
        self.drop = 1.0 - (np.tile(x, 3) / 0.3) ** 2

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = self.neutral.copy()
        v[self.lower, 1] -= float(p[2]) * self.drop
        return v

    def landmarks(self) -> MouthLandmarks:
        n, mid = self.COLS, self.COLS // 2
        e = 6 * n
        return MouthLandmarks(
            eye_outer_left=e,
            eye_inner_left=e + 1,
            eye_inner_right=e + 2,
            eye_outer_right=e + 3,
            corner_left=n - 1,
            corner_right=0,
            upper_lip=2 * n + mid,
            lower_lip=5 * n + mid,
            upper_inner=mid,
            lower_inner=3 * n + mid,
        )


def test_lip_edge_notch_flags_a_zigzag_cut_and_passes_a_smooth_one() -> None:
    from realtime_core.face.checks import LIP_EDGE_NOTCH_LIMIT, lip_edge_notch

    smooth, jagged = _Lips(0.0), _Lips(0.02)
    poses = ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.3, 0.0))
    s = lip_edge_notch(smooth, smooth.landmarks(), poses=poses)
    z = lip_edge_notch(jagged, jagged.landmarks(), poses=poses)
    assert s is not None and z is not None
    # The smooth opening is convex (a straight upper edge, a parabolic lower one): no point of either lip
    # lies on the opening's side of its neighbours' chord.
    assert s < 1e-6
    # The zigzag: every other cut vertex 0.04 IOD (peak to peak) off its neighbours. Each tooth pointing
    # into the opening stands off the chord through the teeth beside it by about that (the chord joins
    # two points at the other extreme, 0.05 IOD along the edge away: most of the 0.04).
    assert z >= 0.5 * 0.04
    assert z > LIP_EDGE_NOTCH_LIMIT
    # check_rig reports it as a warning; the rig still passes the other checks.
    rep = check_rig(jagged, jagged.landmarks(), poses=poses)
    assert rep.passed and rep.warnings and rep.lip_edge_notch_iod == pytest.approx(z)
    assert "lip edge notch" in rep.summary() and "warning" in rep.summary()
    assert check_rig(smooth, smooth.landmarks(), poses=poses).warnings == ()


def test_lip_edge_notch_flags_an_island_in_the_opening() -> None:
    from realtime_core.face.checks import LIP_EDGE_NOTCH_LIMIT, lip_edge_notch

    # A fleck: one triangle (0.04 IOD across) floating in the open mouth, joined to neither lip (what the
    # cut left on Lee Perry-Smith's lip line). It scores half its size: a lip edge would have to leave
    # its course that far to hide it.
    rig = _Lips(0.0)
    n0 = len(rig.neutral)
    fleck = np.array([[0.0, -0.05, 0.0], [0.04, -0.05, 0.0], [0.02, -0.03, 0.0]])
    rig.neutral = np.vstack([rig.neutral, fleck])
    rig.triangles = np.vstack([rig.triangles, [[n0, n0 + 1, n0 + 2]]])
    got = lip_edge_notch(rig, rig.landmarks(), poses=((0.0, 0.0, 0.3, 0.0),))
    assert got == pytest.approx(0.02)
    assert got > LIP_EDGE_NOTCH_LIMIT


def test_lip_edge_notch_joins_a_texture_seam_across_the_lip() -> None:
    """A UV island on the upper lip (its faces on copies of their vertices, which move with them: a Character
    Creator head's inner lips) is one surface with the rest: its edges are no free lip edge. Unjoined, the island's
    border inside the lips' band scored as an edge doubling back (0.035 IOD, over the limit) on a smooth opening."""
    from realtime_core.face.checks import LIP_EDGE_NOTCH_LIMIT, lip_edge_notch, seam_twins

    poses = ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.3, 0.0))
    plain, island = _Lips(0.0), _Lips(0.0)
    n = plain.COLS
    for rig in (plain, island):
        rig.neutral[n : 2 * n, 1] = 0.04  # the upper lip's first row of faces inside the lips' band
    t = island.triangles
    faces = [i for i, f in enumerate(t) if (f < 2 * n).all() and (f % n >= 8).all() and (f % n <= 16).all()]
    used = np.unique(t[faces])
    copy = np.full(len(island.neutral), -1)
    copy[used] = len(island.neutral) + np.arange(len(used))
    island.neutral = np.vstack([island.neutral, island.neutral[used]])
    t[faces] = copy[t[faces]]
    twins = seam_twins(island, poses)
    assert (twins[copy[used]] == used).all() and (twins[: len(used)] == np.arange(len(used))).all()
    # The lip cut's copies (the lower strip's first row) coincide at rest but part: not twins; at the corners, where
    # the opening drops nothing, they stay together and are.
    cut = seam_twins(plain, poses)[3 * n : 4 * n]
    assert (cut[1:-1] == np.arange(3 * n + 1, 4 * n - 1)).all() and (cut[[0, -1]] == [0, n - 1]).all()
    want = lip_edge_notch(plain, plain.landmarks(), poses=poses)
    got = lip_edge_notch(island, island.landmarks(), poses=poses)
    assert want is not None and got is not None
    assert got == pytest.approx(want, abs=1e-9) and got < LIP_EDGE_NOTCH_LIMIT


def test_lip_edge_notch_is_none_for_lips_without_a_free_edge() -> None:
    from realtime_core.face.checks import lip_edge_notch

    rig = _Lips(0.0)
    n = rig.COLS
    t = rig.triangles.copy()
    t[(t >= 3 * n) & (t < 4 * n)] -= 3 * n  # the lower strip hangs from the upper strip's cut row: one sheet
    rig.triangles = t
    assert lip_edge_notch(rig, rig.landmarks(), poses=((0.0, 0.0, 0.0, 0.0),)) is None


def test_a_rig_whose_lips_do_not_part_at_the_midline_fails_the_opening_check() -> None:
    """A cut that misses the lips' contact (Lee Perry-Smith decimated to ~1,500 triangles: the cut ran down the
    lower lip from one corner) opens a wedge beside a corner and leaves the inner-lip points together. Every
    other figure passed; the mouth opening, the inner-lip gap gained per unit mouth_open, is 0 there and 1 for
    the smooth opening."""
    from realtime_core.face.checks import MIN_OPEN_RESPONSE

    smooth = _Lips(0.0)
    poses = ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.3, 0.0))
    rep = check_rig(smooth, smooth.landmarks(), poses=poses)
    assert rep.passed and rep.open_response == pytest.approx(1.0)
    wedge = _Lips(0.0)
    x = np.tile(wedge.x, 3)
    wedge.drop = np.clip((x - 0.15) / 0.15, 0.0, 1.0)  # only the lower lip's left quarter drops
    rep = check_rig(wedge, wedge.landmarks(), poses=poses)
    assert rep.flipped_triangles == 0 and rep.lip_interpenetration_iod == 0 and rep.closure_gap_iod == 0
    assert rep.open_response == pytest.approx(0.0, abs=1e-12) and rep.open_response < MIN_OPEN_RESPONSE
    assert not rep.passed and any("lips part" in f for f in rep.failures)
    assert "mouth opening 0.00" in rep.summary()


def test_lip_edge_shards_counts_each_fleck_and_tooth_over_the_limit() -> None:
    """Shards hanging in the opening (the stylised held-out head's at /a/) score no more than one fleck does;
    their number tells them apart. Flecks added one at a time to the open mouth of :class:`_Lips`, apart
    from each other and from the lips, count one each; the smooth opening counts none. On the zigzag cut
    every tooth pointing into the opening (both lips' edges, the middle 80% of the width) is a place."""
    from realtime_core.face.checks import NOTCH_SPAN, lip_edge_shards

    pose = ((0.0, 0.0, 0.3, 0.0),)
    rig = _Lips(0.0)
    found = lip_edge_shards(rig, rig.landmarks(), poses=pose)
    assert found is not None and found[1] == 0
    for k, x in enumerate((-0.15, 0.0, 0.15), start=1):
        n0 = len(rig.neutral)
        fleck = np.array([[x, -0.05, 0.0], [x + 0.04, -0.05, 0.0], [x + 0.02, -0.03, 0.0]])
        rig.neutral = np.vstack([rig.neutral, fleck])
        rig.triangles = np.vstack([rig.triangles, [[n0, n0 + 1, n0 + 2]]])
        found = lip_edge_shards(rig, rig.landmarks(), poses=pose)
        assert found is not None and found[0] == pytest.approx(0.02) and found[1] == k
    rep = check_rig(rig, rig.landmarks(), poses=pose)
    assert rep.lip_edge_shards == 3 and "at 3 places" in rep.summary()
    jagged = _Lips(0.02)
    found = lip_edge_shards(jagged, jagged.landmarks(), poses=pose)
    assert found is not None
    # Every scored cut vertex but the span's two ends (whose chords reach past it) is a tooth into the
    # opening of one lip or the other: the even columns point down from the upper edge, the odd ones up
    # from the lower edge. One place each.
    x = jagged.x
    scored = np.flatnonzero(np.abs(x) < 0.5 * NOTCH_SPAN * (x[-1] - x[0]))
    assert found[1] == len(scored) - 2


class _Door(_Lips):
    """:class:`_Lips` whose lower lip beyond x = 0.15 (towards the left corner) swings ``degrees`` towards the
    viewer about a vertical axis at x = 0.15 with mouth_open 0.3, as a door on its hinge: its faces turn by
    ``degrees`` (under 90: no flip) to face the right side (-x), so a three-quarter view from the left shows
    their backs past the lip's free edge."""

    HINGE = 0.15

    def __init__(self, degrees: float) -> None:
        super().__init__(0.0)
        self.angle = np.radians(degrees)

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = super().deformed(p)
        a = self.angle * float(p[2]) / 0.3
        door = self.lower[v[self.lower, 0] > self.HINGE]
        r = v[door, 0] - self.HINGE
        v[door, 0] = self.HINGE + r * np.cos(a)
        v[door, 2] = r * np.sin(a)
        return v


def test_lip_backs_seen_flags_a_face_turned_past_edge_on_that_no_other_figure_sees() -> None:
    """Part of a lip turned 76 degrees sideways (the corner slivers of Lee Perry-Smith's rows at /a/ turn
    60-89 degrees) shows its back, drawn dark, to a three-quarter view: a dark shard. It is no flip (< 90
    degrees) and its frontal outline stays convex (no notch); the lip backs seen measure it: the area as seen,
    computed here from the turned faces' corners. The smooth opening shows no back; the same door with a
    flap of lip hanging in front of it is hidden, and is not counted."""
    from realtime_core.face.checks import LIP_BACKS_BAND, LIP_BACKS_LIMIT, LIP_EDGE_NOTCH_LIMIT, lip_backs_seen

    pose = ((0.0, 0.0, 0.3, 0.0),)
    smooth = _Lips(0.0)
    assert lip_backs_seen(smooth, smooth.landmarks(), poses=pose) == (0.0, 0)
    door = _Door(76.0)
    lm = door.landmarks()
    got = lip_backs_seen(door, lm, poses=pose)
    assert got is not None
    rep = check_rig(door, lm, poses=pose)
    assert rep.flipped_triangles == 0 and (rep.lip_edge_notch_iod or 0.0) < LIP_EDGE_NOTCH_LIMIT
    # Independent: the faces of the lower lip's top row (within LIP_BACKS_BAND of the lips' line at rest) that
    # face away from a view 35 degrees to the left (+x): the door's, and the faces over its hinge that turn
    # with it; by their area as projected on that view (the door is flat and nothing lies in front of it).
    v = door.deformed(np.array(pose[0]))
    d = np.array([np.sin(np.radians(35.0)), 0.0, np.cos(np.radians(35.0))])
    on = np.zeros(len(v), dtype=bool)
    on[door.lower[np.abs(door.neutral[door.lower, 1]) < LIP_BACKS_BAND]] = True
    t = door.triangles[on[door.triangles].all(axis=1)]
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    facing = n @ d / np.linalg.norm(n, axis=1)
    t, n, facing = t[facing < -0.17], n[facing < -0.17], facing[facing < -0.17]
    assert len(t) and (v[t, 0] >= door.HINGE - 1e-9).all()
    want = float(np.sum(0.5 * np.linalg.norm(n, axis=1) * -facing))
    assert got[0] == pytest.approx(want, rel=1e-9) and got[1] == len(t)
    assert got[0] > LIP_BACKS_LIMIT
    assert rep.passed and any("show their back" in w for w in rep.warnings) and "lip backs seen" in rep.summary()
    # A flap (facing the viewer) hanging in front of the door from the left hides it.
    n0 = len(door.neutral)
    flap = np.array([[0.1, -0.5, 0.3], [0.6, -0.5, 0.3], [0.35, 0.3, 0.3]])
    door.neutral = np.vstack([door.neutral, flap])
    door.triangles = np.vstack([door.triangles, [[n0, n0 + 1, n0 + 2]]])
    hidden = lip_backs_seen(door, lm, poses=pose)
    assert hidden is not None and hidden[0] < 0.5 * got[0]


class _Chin(_Lips):
    """:class:`_Lips` with a strip of chin skin below (z = 0, x -0.2..0.2, y -0.6..-0.7, facing the viewer), a ledge
    hanging from its lower edge on the right half (x 0..0.2, ``LEDGE`` IOD long, tilted ``REST`` degrees up from
    facing the viewer: its top faces up and forward, as the underside of a chin seen nearly edge-on faces down and
    forward), and a mouth cavity's square (the last four vertices, facing the viewer) 0.3 IOD behind the chin's left
    half. mouth_open p turns the ledge up about its hinge by ``TURN * p / 0.3`` degrees (under 90: no flip) and
    brings the cavity's square to 0.05 IOD in front of the chin, as a jaw that drops the chin behind a cavity that
    stays."""

    LEDGE, REST, TURN = 0.1, 60.0, 50.0

    def __init__(self) -> None:
        super().__init__(0.0)
        lips = len(self.neutral)
        xs = np.linspace(-0.2, 0.2, 5)
        top = np.column_stack([xs, np.full(5, -0.6), np.zeros(5)])
        hinge = np.column_stack([xs, np.full(5, -0.7), np.zeros(5)])
        right = xs[2:]
        a = np.radians(self.REST)
        tip = np.column_stack([right, np.full(3, -0.7 - self.LEDGE * np.cos(a)), np.full(3, self.LEDGE * np.sin(a))])
        cavity = np.array([[-0.2, -0.7, -0.3], [0.0, -0.7, -0.3], [0.0, -0.6, -0.3], [-0.2, -0.6, -0.3]])
        self.neutral = np.vstack([self.neutral, top, hinge, tip, cavity])
        t0, h0, p0, c0 = lips, lips + 5, lips + 10, lips + 13
        t = [[h0 + c, h0 + c + 1, t0 + c + 1] for c in range(4)] + [[h0 + c, t0 + c + 1, t0 + c] for c in range(4)]
        # The ledge's faces: normal (0, sin REST, cos REST), up and towards the viewer.
        t += [[p0 + c, p0 + c + 1, h0 + 2 + c + 1] for c in range(2)]
        t += [[p0 + c, h0 + 2 + c + 1, h0 + 2 + c] for c in range(2)]
        t += [[c0, c0 + 1, c0 + 2], [c0, c0 + 2, c0 + 3]]
        self.triangles = np.vstack([self.triangles, t])
        self.tip, self.cavity = np.arange(p0, p0 + 3), np.arange(c0, c0 + 4)
        self.chin = t0

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = super().deformed(p)
        a = np.radians(self.REST + self.TURN * float(p[2]) / 0.3)
        v[self.tip, 1] = -0.7 - self.LEDGE * np.cos(a)
        v[self.tip, 2] = self.LEDGE * np.sin(a)
        v[self.cavity, 2] = -0.3 + 0.35 * float(p[2]) / 0.3
        return v


def test_skin_seen_dark_sees_a_chin_turned_past_edge_on_and_a_cavity_come_through_it() -> None:
    """The chin's ledge turned 50 degrees (no flip) shows its back to the front view, drawn dark; the cavity's square,
    come in front of the chin, covers two of its cells with the cavity's dark: two shards outside the lips that no lip
    figure sees. The skin seen dark measures them: by hand, the ledge's area as projected on the front view (its
    faces' corners, the shoelace formula) and the two cells the square covers (0.2 x 0.1 IOD, facing the view); the
    chin behind the turned ledge is not counted again. At rest, and with the ledge and the square left where they
    were, nothing is dark."""
    from realtime_core.face.checks import SKIN_DARK_LIMIT, lip_backs_seen, skin_dark_seen

    chin = _Chin()
    lm = chin.landmarks()
    pose = (0.0, 0.0, 0.3, 0.0)
    got = skin_dark_seen(chin, lm, poses=(pose,), cavity_vertices=4)
    assert got is not None
    v = chin.deformed(np.array(pose))
    ledge = chin.triangles[-6:-2]
    xy = v[ledge][:, :, :2]
    shoelace = 0.5 * np.abs(
        (xy[:, 1, 0] - xy[:, 0, 0]) * (xy[:, 2, 1] - xy[:, 0, 1])
        - (xy[:, 2, 0] - xy[:, 0, 0]) * (xy[:, 1, 1] - xy[:, 0, 1])
    )
    want = float(shoelace.sum()) + 0.2 * 0.1
    assert float(shoelace.sum()) == pytest.approx(0.2 * chin.LEDGE * abs(np.cos(np.radians(110.0))), rel=1e-9)
    assert got[0] == pytest.approx(want, rel=1e-9) and got[1] == 4 + 4 and got[2] == pose
    assert got[0] > SKIN_DARK_LIMIT
    rest = (0.0, 0.0, 0.0, 0.0)
    assert skin_dark_seen(chin, lm, poses=(rest,), cavity_vertices=4) == (0.0, 0, ())
    assert skin_dark_seen(_Lips(0.0), lm, poses=(pose,)) == (0.0, 0, ())
    rep = check_rig(chin, lm, poses=(pose,), cavity_vertices=4)
    assert rep.flipped_triangles == 0 and rep.skin_dark_iod2 == pytest.approx(want, rel=1e-9)
    assert lip_backs_seen(chin, lm, poses=(pose,), skip_vertices=4) == (0.0, 0)
    assert any("drawn dark" in w for w in rep.warnings) and f"skin seen dark {1000 * want:.2f}e-3" in rep.summary()
    # The cavity's square is dark by its colour, not by its facing: counted as a face of the rig's own, it is lit
    # and covers the chin as any skin does (only the ledge's back remains).
    alone = skin_dark_seen(chin, lm, poses=(pose,), cavity_vertices=0)
    assert alone is not None and alone[0] == pytest.approx(float(shoelace.sum()), rel=1e-9)


class _Slit(_Lips):
    """:class:`_Lips` over a mouth cavity's square (the last four vertices, facing the viewer, 0.3 IOD behind the lips,
    wider than the mouth), its lower strip held ``apart`` more mouth_open at every pose: lips that never meet, the
    cavity seen between them."""

    def __init__(self, apart: float) -> None:
        super().__init__(0.0)
        self.apart = apart
        c0 = len(self.neutral)
        square = np.array([[-0.4, -0.3, -0.3], [0.4, -0.3, -0.3], [0.4, 0.3, -0.3], [-0.4, 0.3, -0.3]])
        self.neutral = np.vstack([self.neutral, square])
        self.triangles = np.vstack([self.triangles, [[c0, c0 + 1, c0 + 2], [c0, c0 + 2, c0 + 3]]])

    def deformed(self, p: np.ndarray) -> np.ndarray:
        return super().deformed(np.asarray(p, dtype=np.float64) + np.array([0.0, 0.0, self.apart, 0.0]))


def test_closed_lips_seen_dark_measures_the_cavity_seen_between_lips_held_apart() -> None:
    """Lips held 0.05 apart at the middle over a dark cavity: at the closure pose (and every pressed-lip pose) the
    front view sees the cavity through a lens between the strips, 0.05 (1 - (x / 0.3)^2) high, of area
    0.05 * 0.6 * 2/3 = 0.02 IOD^2 by hand (the three-quarter views see it narrower); the grid of LIPS_DARK_STEP
    measures it within 2 %, and the rig fails on it (here the closure gap sees the middle pair apart too; on the
    mirrored 1,428-triangle Lee Perry-Smith it did not). Lips that meet show nothing dark, and a square that is no
    cavity (counted as the rig's own face, lit) is no slit."""
    from realtime_core.face.checks import BILABIAL_POSES, LIPS_DARK_LIMIT, lips_dark_seen

    slit = _Slit(0.05)
    lm = slit.landmarks()
    closed = (0.0, 0.0, 0.0, 0.0)
    got = lips_dark_seen(slit, lm, poses=(closed, *BILABIAL_POSES), cavity_vertices=4)
    assert got is not None and got[0] == pytest.approx(0.05 * 0.6 * 2 / 3, rel=0.02) and got[1] == closed
    assert got[0] > LIPS_DARK_LIMIT
    assert lips_dark_seen(_Slit(0.0), lm, poses=(closed, *BILABIAL_POSES), cavity_vertices=4) == (0.0, ())
    assert lips_dark_seen(slit, lm, poses=(closed,), cavity_vertices=0) == (0.0, ())
    rep = check_rig(slit, lm, poses=((0.0, 0.0, 0.3, 0.0),), cavity_vertices=4, expression_poses=())
    assert not rep.passed and any("slit between closed lips" in f for f in rep.failures)
    assert rep.lips_dark_iod2 == pytest.approx(got[0], rel=1e-9) and "closed lips seen dark" in rep.summary()
    assert check_rig(_Slit(0.0), lm, poses=((0.0, 0.0, 0.3, 0.0),), cavity_vertices=4).lips_dark_iod2 == 0.0


def test_skin_dark_poses_keep_the_widest_openings_and_every_parameters_ends() -> None:
    """The poses the skin seen dark is measured at: each parameter's largest and smallest value among the checked
    poses, and every pose within SKIN_DARK_WIDEST of the widest opening (the measured frames at 0.45 beside 0.465)."""
    from realtime_core.face.checks import SKIN_DARK_WIDEST, skin_dark_poses

    kept = skin_dark_poses(EXTREME_POSES)
    p = np.array(EXTREME_POSES)
    assert set(kept) <= set(EXTREME_POSES) and len(set(kept)) == len(kept) < len(EXTREME_POSES)
    for j in range(4):
        assert np.array(kept)[:, j].max() == p[:, j].max() and np.array(kept)[:, j].min() == p[:, j].min()
    wide = {q for q in EXTREME_POSES if q[2] >= p[:, 2].max() - SKIN_DARK_WIDEST}
    assert len(wide) > 1 and wide <= set(kept)


class _Shelf(_Lips):
    """:class:`_Lips` with a shelf hanging from the upper strip's cut row: a row of faces from the cut (y = 0, z = 0)
    down and forward to y = -0.02, z = 0.05, facing up (the lower lip's top, cut off with the upper lip where a knife
    ran below the lips' meeting: the 3,810-triangle Lee Perry-Smith copy), which stays with the upper strip.
    ``follows``: the shelf hangs from the lower strip's cut row instead and drops with it (the lower lip's top where
    it belongs)."""

    def __init__(self, follows: bool) -> None:
        super().__init__(0.0)
        n = self.COLS
        shelf = np.column_stack([self.x, np.full(n, -0.02), np.full(n, 0.05)])
        s0 = len(self.neutral)
        self.neutral = np.vstack([self.neutral, shelf])
        t = []
        for c in range(n - 1):
            a, b = (3 * n if follows else 0) + c, s0 + c  # a strip's cut row, the shelf's row
            t += [[a, b + 1, a + 1], [a, b, b + 1]]
        self.triangles = np.vstack([self.triangles, t])
        self.shelf = np.arange(s0, s0 + n)
        self.follows = follows

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = super().deformed(p)
        if self.follows:
            v[self.shelf, 1] -= float(p[2]) * self.drop[: self.COLS]
        return v

    def pairs(self) -> np.ndarray:
        n = self.COLS
        return np.column_stack([np.arange(n), 3 * n + np.arange(n)])


def test_lip_tops_carried_sees_the_lower_lips_top_moving_with_the_upper_lip() -> None:
    """A strip of the lower lip's top that the cut left on the upper lip hangs under it, lit from above: a pale line
    between the lips at /m/ and a pale band over the slit at /u/, which no other figure sees (no flip, no notch, no
    back). The lip tops carried measure it: its area as seen from the front, here its width times its drop (0.6 x
    0.02 IOD), at rest and when the lips part. The same shelf on the lower lip, dropping with it, counts nothing, and
    the smooth lips have no lip top."""
    from realtime_core.face.checks import LIP_TOPS_LIMIT, lip_tops_carried

    poses = ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.3, 0.0))
    smooth = _Lips(0.0)
    assert lip_tops_carried(smooth, smooth.landmarks(), poses=poses, lip_pairs=_Shelf(False).pairs()) is None
    carried = _Shelf(False)
    lm = carried.landmarks()
    got = lip_tops_carried(carried, lm, poses=poses, lip_pairs=carried.pairs())
    assert got is not None
    assert got[0] == pytest.approx(0.6 * 0.02, rel=1e-9) and got[1] == 2 * (carried.COLS - 1)
    assert got[0] > LIP_TOPS_LIMIT
    follows = _Shelf(True)
    assert lip_tops_carried(follows, lm, poses=poses, lip_pairs=follows.pairs()) in (None, (0.0, 0))
    rep = check_rig(carried, lm, poses=poses, lip_pairs=carried.pairs())
    assert rep.passed and rep.flipped_triangles == 0 and rep.lip_tops_iod2 == pytest.approx(got[0])
    assert (
        any("lip-top faces" in w for w in rep.warnings) and f"lip tops carried {1000 * got[0]:.2f}e-3" in rep.summary()
    )
    assert (rep.lip_edge_notch_iod or 0.0) <= 0.015 and (rep.lip_backs_iod2 or 0.0) == 0.0
    assert not any("lip-top" in w for w in check_rig(follows, lm, poses=poses, lip_pairs=follows.pairs()).warnings)


class _LoweredUpperLip(_Lips):
    """:class:`_Lips` whose lowered upper lip (upper_lip_raise < 0) moves both strips down by as much, and
    also drops the lower strip by ``opens`` times it: a map that answers a lowered upper lip with a jaw
    opening (the streamed ARKit map before branch i12lipm: the lips parted at every /m/)."""

    def __init__(self, opens: float) -> None:
        super().__init__(0.0)
        self.opens = opens

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = super().deformed(p)
        down = max(-float(p[0]), 0.0)
        v[:, 1] -= down
        v[self.lower, 1] -= self.opens * down * self.drop
        return v


def test_the_lip_gap_at_m_flags_a_rig_that_opens_its_lips_for_a_lowered_upper_lip() -> None:
    """The closure figure (mouth_open = -rest gap) does not see it: the lips open only at the pressed
    bilabial pose, whose gap the check reports (a warning over 0.01 IOD; the rig still passes)."""
    from realtime_core.face.checks import BILABIAL_POSES, bilabial_gap

    assert BILABIAL_POSES and all(p[2] == 0.0 and p[0] < 0 for p in BILABIAL_POSES)
    lowered = max(-p[0] for p in BILABIAL_POSES)  # the furthest-lowered upper lip: 0.014 IOD
    poses = ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.3, 0.0))
    opening, closing = _LoweredUpperLip(2.0), _LoweredUpperLip(0.0)
    # The inner-lip landmarks sit at the midline (drop 1): the gap is 2 x the lowering.
    assert bilabial_gap(opening, opening.landmarks()) == pytest.approx(2.0 * lowered)
    rep = check_rig(opening, opening.landmarks(), poses=poses)
    assert rep.closure_gap_iod == pytest.approx(0.0, abs=1e-12) and rep.lip_interpenetration_iod == 0
    assert rep.bilabial_gap_iod == pytest.approx(2.0 * lowered) and rep.bilabial_gap_iod > 0.01
    assert rep.passed and any("/m/" in w for w in rep.warnings)
    assert f"lip gap at /m/ {2.0 * lowered:.4f} IOD" in rep.summary()
    rep = check_rig(closing, closing.landmarks(), poses=poses)
    assert rep.bilabial_gap_iod == pytest.approx(0.0, abs=1e-12) and rep.warnings == () and rep.passed


def test_the_pose_bound_keeps_checked_poses_and_gives_the_hull_point_nearest_any_other() -> None:
    bound = checked_bound()
    v = np.array(bound.poses)
    assert set(EXTREME_POSES) < set(bound.poses)
    rng = np.random.default_rng(12)
    inside = rng.dirichlet(np.ones(len(v)), 50) @ v  # convex combinations of the checked poses
    np.testing.assert_array_equal(bound(inside), inside)
    np.testing.assert_array_equal(bound(np.zeros(4)), np.zeros(4))  # rest: the mouth_open 0 face of the hull
    closure = np.array([0.0, 0.0, -0.0111, 0.0])  # the ARKit test files' closure pose: their lips close
    np.testing.assert_array_equal(bound(closure), closure)
    np.testing.assert_allclose(bound(np.array([0.0, 0.0, -1.0, 0.0])), [0.0, 0.0, -CLOSURE_REACH, 0.0], atol=1e-12)
    # The typical ranges' corner where ARKit heads' lips crossed (docs/animation.md, "Sweep"), and random poses
    # up to twice the ranges: each goes to the hull point q nearest it, which holds iff (x - q) . (v - q) <= 0
    # for every vertex v of the hull (the projection onto a convex set).
    far = np.vstack([[0.06, -0.15, 0.0, -0.1], rng.normal(size=(40, 4)) * [0.1, 0.25, 0.6, 0.15]])
    q = bound(far)
    assert q.shape == far.shape and bound.contains(q).all()
    assert not bound.contains(far[0])
    for x, qi in zip(far, q):
        assert np.max((v - qi) @ (x - qi)) <= 1e-9 * np.linalg.norm(x - qi)
    np.testing.assert_allclose(bound(far[3]), q[3])  # a single pose as in a batch
    with pytest.raises(ConfigError):
        PoseBound(poses=((0.0, 0.0, 0.0, 0.0), (0.1, 0.0, 0.0, 0.0), (0.0, 0.1, 0.0, 0.0)))


class _Seam(_Fold):
    """The flat grid with a copy of its vertex 1 (vertex 9, as a second mesh's vertex at the seam would be) that
    drops by ``drop`` x mouth_open while vertex 1 stays: a seam that opens with the jaw; nothing folds."""

    def __init__(self, drop: float) -> None:
        super().__init__()
        self.neutral = np.vstack([self.neutral, self.neutral[1]])
        self.drop = drop

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = self.neutral.copy()
        v[9, 1] -= self.drop * p[2]
        return v


def test_check_fails_a_seam_between_meshes_that_opens_and_reports_its_gap() -> None:
    lm = _fold_landmarks()
    iod = 2.0  # the face frame of this grid: eye corners at x = 0 and 2
    pairs = np.array([[1, 9]])
    limits = RigCheckLimits(min_open_response=0.0)  # the grid's "lips" (one vertex) never part
    opening = check_rig(_Seam(0.1), lm, joined_pairs=pairs, limits=limits)
    widest = max(float(p[2]) for p in EXTREME_POSES)
    assert opening.seam_gap_iod == pytest.approx(0.1 * widest / iod)
    assert opening.failures == (
        f"the seam between the head's meshes opens by {opening.seam_gap_iod:.4f} IOD (> 0.001)",
    )
    assert "parts' seam gap" in opening.summary()
    shut = check_rig(_Seam(0.0), lm, joined_pairs=pairs, limits=limits)
    assert shut.seam_gap_iod == 0.0 and shut.passed
    # Not measured without pairs: the report as before.
    plain = check_rig(_Seam(0.1), lm, limits=limits)
    assert plain.seam_gap_iod is None and plain.passed and "seam" not in plain.summary()


def test_a_heads_own_closure_reach_stops_mouth_open_where_its_lips_meet() -> None:
    """The bound's closure pose is (0, 0, -reach, 0): a head whose lips touch at rest (reach 0) never gets a
    negative mouth_open, one modelled 0.0111 IOD apart closes them and no further; the default is CLOSURE_REACH."""
    assert checked_bound() is checked_bound(None, CLOSURE_REACH)
    for reach in (0.0, 0.0111):
        bound = checked_bound(None, reach)
        assert (0.0, 0.0, -reach, 0.0) in bound.poses and min(p[2] for p in bound.poses) == -reach
        np.testing.assert_allclose(bound(np.array([0.0, 0.0, -1.0, 0.0])), [0.0, 0.0, -reach, 0.0], atol=1e-12)
        pressed = np.array([0.0, 0.0, -reach - 0.005, 0.0])
        assert not bound.contains(pressed) and checked_bound().contains(pressed)
    assert checked_bound(None, 0.0111) is checked_bound(None, 0.0111 + 1e-9)  # one hull for gaps alike to 1e-6
    for bad in (-0.01, 1.0, float("nan")):
        with pytest.raises(ConfigError, match="closure reach"):
            checked_bound(None, bad)


class _Sneer(_Lips):
    """:class:`_Lips` (straight cut) whose mouth_open p also lowers the upper strip by ``p * drop(x)``: ``peaked``,
    a tent from the middle (drop 0.6 |x| / 0.3, the edge drawn to a peak); else an arc with the same drop at the
    corners (0.6 (x / 0.3)^2)."""

    def __init__(self, peaked: bool) -> None:
        super().__init__(zigzag=0.0)
        x = np.tile(self.x, 3)
        self.upper = np.arange(0, 3 * self.COLS)
        self.sag = 0.6 * (np.abs(x) / 0.3 if peaked else (x / 0.3) ** 2)

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = super().deformed(p)
        v[self.upper, 1] -= float(p[2]) * self.sag
        return v


def test_upper_lip_peak_reads_a_tent_and_not_an_arc_with_the_same_corners() -> None:
    from realtime_core.face.checks import PEAK_COLUMNS, PEAK_POSE, upper_lip_peak

    tent, arc = _Sneer(peaked=True), _Sneer(peaked=False)
    p_tent, e_tent = upper_lip_peak(tent, tent.landmarks())
    p_arc, e_arc = upper_lip_peak(arc, arc.landmarks())
    # Both lower the corners alike; each edge is symmetric and lies below the cut (y 0) it starts from.
    pose = np.array(PEAK_POSE)
    lm = tent.landmarks()
    corners = [lm.corner_left, lm.corner_right]
    assert np.allclose(tent.deformed(pose)[corners], arc.deformed(pose)[corners])
    for e in (e_tent, e_arc):
        sides = np.arange(len(e)) != len(e) // 2
        assert len(e) == 2 * len(PEAK_COLUMNS) + 1 and np.allclose(e, e[::-1]) and np.all(e[sides] < -1.0)
    # An arc a + b x^2 fits the arc's sides exactly: no peak; the tent's middle lies above the arc through its sides.
    assert abs(p_arc) < 1e-9
    assert p_tent > 0.02
    # Turned and scaled, the head reads the same (IOD, in the face's own frame).
    rot = np.array([[np.cos(0.4), 0.0, np.sin(0.4)], [0.0, 1.0, 0.0], [-np.sin(0.4), 0.0, np.cos(0.4)]])

    class Moved:
        neutral = 3.0 * tent.neutral @ rot.T + 1.0
        triangles = tent.triangles

        def deformed(self, p: np.ndarray) -> np.ndarray:
            return 3.0 * tent.deformed(p) @ rot.T + 1.0

    assert upper_lip_peak(Moved(), tent.landmarks())[0] == pytest.approx(p_tent, abs=1e-9)


class _Crease(_Lips):
    """:class:`_Lips` whose lower strip's middle column sinks ``depth`` IOD away from the viewer (-z) at
    mouth_open 0.3 (in proportion to mouth_open): the faces either side of it tilt towards it, a V crease along
    the column, as a crumpled lower lip folds; no face flips and no edge stretches past the limit (4x)."""

    def __init__(self, depth: float) -> None:
        super().__init__(0.0)
        self.depth = depth
        self.column = self.lower[np.isclose(self.neutral[self.lower, 0], 0.0)]

    def deformed(self, p: np.ndarray) -> np.ndarray:
        v = super().deformed(p)
        v[self.column, 2] -= self.depth * float(p[2]) / 0.3
        return v


def test_lip_crumple_measures_the_crease_a_lip_folds_into() -> None:
    """The smooth opening folds no lip face (0 degrees); a column of the lower lip sunk by h between columns 0.025
    IOD apart makes a valley of 2 atan(h / 0.025) along it (each side's faces tilt by atan(h / 0.025)), and over
    the limit the report warns (no other figure fails: no flip, no stretch)."""
    from realtime_core.face.checks import LIP_CRUMPLE_LIMIT, lip_crumple

    poses = ((0.0, 0.0, 0.15, 0.0), (0.0, 0.0, 0.3, 0.0))
    smooth = _Lips(0.0)
    got = lip_crumple(smooth, smooth.landmarks(), poses=poses)
    assert got is not None and got[0] == pytest.approx(0.0, abs=1e-6)
    h = 0.025 * np.tan(np.radians(40.0))
    crease = _Crease(h)
    got = lip_crumple(crease, crease.landmarks(), poses=poses)
    assert got is not None
    assert got[0] == pytest.approx(2 * np.degrees(np.arctan(h / 0.025)), abs=1e-6) and got[1] == poses[1]
    assert got[0] > LIP_CRUMPLE_LIMIT
    rep = check_rig(crease, crease.landmarks(), poses=poses)
    assert rep.flipped_triangles == 0 and rep.sliver_stretch is not None and rep.sliver_stretch < 4.0
    assert rep.passed and any("crease" in w for w in rep.warnings) and "lip crumple 80 deg" in rep.summary()
    # A bulge towards the viewer is a ridge along the column: its sides' valleys are half as deep, 40 degrees.
    bulge = _Crease(-h)
    got = lip_crumple(bulge, bulge.landmarks(), poses=poses)
    assert got is not None and got[0] == pytest.approx(np.degrees(np.arctan(h / 0.025)), abs=1e-6)
