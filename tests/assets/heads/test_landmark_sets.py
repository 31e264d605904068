"""Landmarks found with alternatives (FoundLandmarks): kept with them in the landmark cache, and rigged from in turn
by rig_checked when every rig from the found set fails its checks."""

from __future__ import annotations

import json

import numpy as np

from assets.heads.head import LANDMARK_CACHE_VERSION, cached_finder, rig_checked
from assets.heads.landmarks import FoundLandmarks
from assets.heads.mesh import HeadMesh, load_mesh
from clients.render.landmarks import MEDIAPIPE_INDEX

# The MediaPipe canonical face's own vertex indices are MediaPipe's landmark indices ("left" is the face's own left).
MEDIAPIPE = MEDIAPIPE_INDEX


def test_a_rig_from_landmarks_that_fail_is_made_again_from_their_alternatives(shared_data):
    """The MediaPipe face with its upper inner-lip point on the nose tip (a landmark set that cannot rig: the cut runs
    through the nose, 80 flips at /a/) given as found with the face's own points as the alternative: every try from the
    found set fails, the alternative's rig passes, is the rig made from those points directly, and its meta and the
    progress lines say which set passed and why the first did not. Found first, the good set is rigged once (no
    alternative tried, no landmark_set in its meta)."""
    m = load_mesh(shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj")
    good = {k: m.vertices[i].tolist() for k, i in MEDIAPIPE.items()}
    bad = {**good, "upper_inner": good["nose_tip"]}
    lines: list[str] = []
    rig, _, report = rig_checked(m, FoundLandmarks(bad, (good,)), progress=lines.append)
    assert report.passed
    assert rig.meta["landmark_set"] == 1
    (first,) = rig.meta["landmark_sets_failed"]
    assert first["set"] == 0 and first["failures"]
    assert any("rigging from another set of them (1 of 1" in line for line in lines)
    direct, _, direct_report = rig_checked(m, good)
    np.testing.assert_array_equal(rig.neutral, direct.neutral)
    assert (rig.matrix != direct.matrix).nnz == 0
    assert direct_report.passed and "landmark_set" not in direct.meta
    lines.clear()
    once, _, _ = rig_checked(m, FoundLandmarks(good, (bad,)), progress=lines.append)
    assert "landmark_set" not in once.meta and "landmark_sets_failed" not in once.meta
    assert not any("another set" in line for line in lines)
    assert (once.matrix != direct.matrix).nnz == 0


def test_the_landmark_cache_keeps_a_finders_alternatives(tmp_path):
    """cached_finder keeps the alternatives with the points (JSON) and gives both back on the next load without
    asking the finder; its file name carries the cache version, so a file kept before alternatives were (whose key
    had no version) is not read."""
    box = HeadMesh(
        vertices=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64),
        triangles=np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]),
        name="box",
    )
    calls = []

    def finder(mesh):
        calls.append(mesh.name)
        return FoundLandmarks({"nose_tip": [0.0, 0.0, 1.0]}, ({"nose_tip": [0.0, 0.1, 1.0]}, {"nose_tip": [0, 0, 0.9]}))

    first = cached_finder(finder, tmp_path)(box)
    again = cached_finder(finder, tmp_path)(box)
    assert calls == ["box"]
    assert isinstance(again, FoundLandmarks)
    assert dict(again) == {"nose_tip": [0.0, 0.0, 1.0]} == dict(first)
    assert again.alternatives == ({"nose_tip": [0.0, 0.1, 1.0]}, {"nose_tip": [0, 0, 0.9]})
    (kept,) = (tmp_path / "landmarks").iterdir()
    assert json.loads(kept.read_text())["alternatives"][0] == {"nose_tip": [0.0, 0.1, 1.0]}
    assert LANDMARK_CACHE_VERSION >= 2


def test_a_rig_whose_lip_crumples_is_made_once_more_and_kept_only_if_it_crumples_less(shared_data):
    """rig_checked makes a rig that passes with its lip crumple over the limit once more with the corners' depress
    read off mouth_open left uncorrected (rig_head, open_depress_left), and keeps the first rig, to the bit, unless
    the new one passes and crumples less. The MediaPipe face judged with the limit at 10 degrees (its rig crumples 33):
    the retry is made and said; whichever rig is returned passes and crumples no more than the first."""
    from realtime_core.face.checks import RigCheckLimits

    m = load_mesh(shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj")
    good = {k: m.vertices[i].tolist() for k, i in MEDIAPIPE.items()}
    first, _, first_report = rig_checked(m, good)
    assert first_report.passed and first_report.lip_crumple_deg is not None
    assert "open_depress_left" not in first.meta
    lines: list[str] = []
    limits = RigCheckLimits(max_lip_crumple=10.0)
    rig, _, report = rig_checked(m, good, progress=lines.append, limits=limits)
    assert any("lip crumple" in line and "left uncorrected" in line for line in lines)
    assert report.passed and report.lip_crumple_deg is not None
    assert report.lip_crumple_deg <= first_report.lip_crumple_deg
    if "open_depress_left" in rig.meta:
        assert report.lip_crumple_deg < first_report.lip_crumple_deg
        assert any("lip crumple" in f for a in rig.meta["rig_attempts"] for f in a["failures"])
    else:
        assert (rig.matrix != first.matrix).nnz == 0 and "rig_attempts" not in rig.meta
