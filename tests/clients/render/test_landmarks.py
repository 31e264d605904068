"""Automatic landmarks: MediaPipe on an offscreen render, cast back onto the mesh."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from assets.heads.landmarks import shipped_landmarks
from assets.heads.mesh import load_mesh
from clients.render.landmarks import find_landmarks
from facecast.cli import main

# Offscreen OpenGL renders and MediaPipe on real heads.
pytestmark = [pytest.mark.system, pytest.mark.slow]


def test_automatic_landmarks_agree_with_the_hand_picked_ones(shared_data):
    lps = shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    mesh = load_mesh(lps)
    auto = find_landmarks(mesh)
    ref = json.loads(shipped_landmarks(lps).read_text())["landmarks"]
    v = mesh.vertices
    iod = np.linalg.norm(
        0.5 * (v[ref["eye_outer_left"]] + v[ref["eye_inner_left"]])
        - 0.5 * (v[ref["eye_outer_right"]] + v[ref["eye_inner_right"]])
    )
    err = {k: float(np.linalg.norm(np.asarray(p) - v[ref[k]]) / iod) for k, p in auto.items()}
    assert max(err.values()) < 0.2, err  # hand picks and MediaPipe differ by a few vertices
    assert np.mean(list(err.values())) < 0.1, err


def test_a_human_like_head_rigs_with_no_manual_landmark(tmp_path, shared_data, capsys):
    head = tmp_path / "someone.glb"  # a name nobody shipped landmarks for
    shutil.copy(shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb", head)
    rc = main(["rig", str(head), "-o", str(tmp_path / "r.npz"), "--keep-failing"])
    assert rc == 0 and (tmp_path / "r.npz").is_file()
    assert "automatic landmarks" not in capsys.readouterr().err


@pytest.fixture(scope="module")
def automatic_rig(shared_data):
    """Lee Perry-Smith rigged from automatic landmarks as every command rigs a mesh (built once: rigging it
    takes minutes; :func:`assets.heads.head.rig_checked`, its first rig failing, rigs it twice)."""
    from assets.heads.head import Head, rig_checked

    mesh = load_mesh(shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    rig, rigged, _ = rig_checked(mesh, find_landmarks(mesh), landmark_source="automatic landmarks")
    return Head(rig, rigged)


def test_automatic_landmarks_do_not_over_open_the_jaw(automatic_rig):
    """Automatic inner-lip points sit a few hundredths of an IOD off the hand ones and read a small
    lip response; dividing the mouth-open column by it opened the jaw 2.65x (152 flipped triangles,
    a long face at /a/). The rescale must stay bounded and the rig must not fold like that at any
    open pose the shipped models produce."""
    from assets.heads.head import head_checks
    from assets.heads.rigging import OPEN_RESPONSE_RANGE
    from realtime_core.face.checks import EXTREME_POSES

    rig = automatic_rig.rig
    assert rig.meta.get("open_rescaled", 1.0) <= 1.0 / OPEN_RESPONSE_RANGE[0] + 1e-3, rig.meta
    open_poses = tuple(p for p in EXTREME_POSES if p[2] >= 0.05)
    assert len(open_poses) >= 40  # most of the checked poses open the mouth
    rep = head_checks(automatic_rig, poses=open_poses)
    # 152 flips and stretch 30.7 with the unbounded rescale; 33 and 8.1 with the cut started inside the
    # crease between the lips (the automatic inner-lip points, before front_contact moved them to its front).
    # Bounded here well below both failures above, so a jaw that over-opens again still fails (the full
    # checks, stretch <= 4, are the next test's).
    assert rep.flipped_triangles == 0 and rep.max_edge_stretch < 6.0, rep
    assert rep.lip_interpenetration_iod <= 0.005 and rep.closure_gap_iod <= 0.01, rep


def test_the_automatic_landmark_rig_passes_every_check(automatic_rig, tmp_path):
    """Every check at every measured pose, on the rig as built and as read back from its file. RIG_ALGORITHM
    21: 1 flipped triangle at closed lips with the corners up (the lip-contact push was spread over the
    crease walls removed afterwards; a rig file dropped the spread altogether) and one edge by the right
    corner stretched 5.26x at the widest opening; 22: 0 flips, 4.63; 23: the fold repair on the final mesh,
    chosen as the first rig fails, 0 flips, 3.41; 24: clean lips with the repair on the final mesh, the second
    rig (the first, clean lips with the repair across the walls, stretches 4.72), 0 flips, 3.44
    (docs/animation.md, test set)."""
    from assets.heads.head import Head, head_checks
    from assets.heads.rigfile import load_rig, save_rig

    meta = automatic_rig.rig.meta
    assert meta.get("clean_lips") and meta.get("fold_repair_mesh") == "final", meta.get("rig_attempts")
    rep = head_checks(automatic_rig)
    assert rep.passed, rep
    rig, mesh = load_rig(save_rig(automatic_rig.rig, automatic_rig.mesh, tmp_path / "r.npz"))
    assert rig.contact_spread is not None
    rep = head_checks(Head(rig, mesh))
    assert rep.passed, rep


def test_automatic_inner_lip_points_move_to_the_front_of_the_lips_contact(shared_data):
    """On Lee Perry-Smith's closed lips the automatic inner-lip points land inside the crease (0.03 IOD up
    its lower wall); rigging moves both to the one vertex at the crease's front, the hand-picked one."""
    from assets.heads.rigging import CONTACT_REACH, front_contact, mouth_landmarks, resolve_landmarks
    from realtime_core.face import face_frame

    lps = shared_data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    mesh = load_mesh(lps)
    v = mesh.vertices
    ref = json.loads(shipped_landmarks(lps).read_text())["landmarks"]
    auto = resolve_landmarks(find_landmarks(mesh), v, "automatic")
    snap = {k: int(np.argmin(np.linalg.norm(v - p, axis=1))) for k, p in auto.items()}
    frame = face_frame(v, mouth_landmarks(snap))
    assert snap["lower_inner"] != ref["lower_inner"]  # the render's point: inside the crease
    got = front_contact(v, mesh.triangles, snap["lower_inner"], frame.axes[2], reach=CONTACT_REACH * frame.iod)
    assert got == ref["lower_inner"]
