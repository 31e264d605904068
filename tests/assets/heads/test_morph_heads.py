"""Heads driven by their own morph targets: name matching, paper 002 eq. 4 with bounds, the built-in
head as an ARKit file, visemes, user maps, exports."""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from assets.heads.glb import head_glb, mesh_glb
from assets.heads.head import builtin_morph_head, resolve_head
from assets.heads.mesh import HeadMesh
from assets.heads.targets import VISEME_ARKIT, canonical_name, match_targets
from realtime_core.face.keyframes import KeyframeMap
from tests.prerequisites import require_module

# The built-in head (downloaded on first use) and real glTF files.
pytestmark = pytest.mark.system


@pytest.fixture(scope="module")
def builtin_morph():
    return builtin_morph_head()


def test_bounded_keyframe_solve_matches_scipy_bvls():
    rng = np.random.default_rng(3)
    kf = rng.normal(size=(12, 90))
    kf[3] = kf[2] + 1e-3 * rng.normal(size=90)  # a near duplicate, as target sets often have
    src = rng.normal(size=(5, 90))
    km = KeyframeMap.from_reference(kf, src)
    chol = np.linalg.cholesky(km.gram)
    for _ in range(50):
        x = rng.normal(size=5) * 2
        w = km.weights(x)
        f = km.cross @ x
        ref = lsq_linear(chol.T, np.linalg.solve(chol, f), bounds=(0, 1), method="bvls").x

        def obj(b, f=f):
            return 0.5 * b @ km.gram @ b - f @ b

        assert w.min() >= 0 and w.max() <= 1
        assert obj(w) <= obj(ref) + 1e-9 * max(1.0, abs(obj(ref)))
    # Unbounded eq. 4 reproduces a motion that lies in the keyframes' span.
    km2 = KeyframeMap.from_reference(kf, kf[:4], ridge=1e-12, lo=-10, hi=10)
    np.testing.assert_allclose(km2.weights(np.array([0.2, 0.1, 0, 0.3]))[:4], [0.2, 0.1, 0, 0.3], atol=1e-6)


@pytest.mark.parametrize(
    ("name", "want"),
    [
        ("jawOpen", "jawOpen"),
        ("JawOpen", "jawOpen"),
        ("jaw_open", "jawOpen"),
        ("blendShape1.jawOpen", "jawOpen"),
        ("mouthSmile_L", "mouthSmileLeft"),
        ("mouthSmile_R", "mouthSmileRight"),
        ("MouthSmileLeft", "mouthSmileLeft"),
        ("mouth_smile_left", "mouthSmileLeft"),
        ("mouthSmile.L", "mouthSmileLeft"),
        ("eyeBlink_l", "eyeBlinkLeft"),
        ("mouthLeft", "mouthLeft"),
        ("viseme_aa", "viseme:aa"),
        ("viseme_PP", "viseme:PP"),
        ("v_ou", "viseme:U"),
        ("Fcl_MTH_A", "viseme:aa"),
        ("aa", "viseme:aa"),
        ("ih", "viseme:I"),
        ("AK_09_JawOpen", "jawOpen"),
        ("Genesis8Female__jawOpen", "jawOpen"),
        ("CTRL_expressions_mouthSmile_L", "mouthSmileLeft"),
        ("CC_Base_Body.Mouth_Up_Upper_L", "mouthUpperUpLeft"),
        ("Mouth_Down_Lower_R", "mouthLowerDownRight"),
        ("Mouth_Roll_In_Upper_L", None),  # a part of mouthRollUpper (target_part), not the whole target
        ("Head_aa", None),  # a viseme only as the whole name or after a viseme prefix
        ("Body", None),
        ("Key 1", None),
    ],
)
def test_target_names_are_recognised(name, want):
    assert canonical_name(name) == want


def _arkit_file(tmp_path, builtin, rename):
    m = builtin.mesh
    targets = {rename(k): v for k, v in m.targets.items()}
    mesh = HeadMesh(vertices=m.vertices, triangles=m.triangles, colors=m.colors, name="x", targets=targets)
    path = tmp_path / "arkit_head.glb"
    path.write_bytes(mesh_glb(mesh))
    return path


def test_an_arkit_glb_animates_through_its_own_targets_with_no_rig_step(tmp_path, builtin_morph):
    def rename(k):  # the common spellings: mouthSmile_L, JawOpen, blendShape1. prefixes
        k = k.replace("Left", "_L").replace("Right", "_R")
        return "blendShape1." + k[0].upper() + k[1:]

    path = _arkit_file(tmp_path, builtin_morph, rename)
    head = resolve_head(path)  # no landmarks anywhere: must not need a rig
    # The 22 targets speech drives (jaw, mouth: 19 before the antagonists' netting, whose re-solve also recruits
    # mouthPressLeft, mouthRollLower and mouthShrugLower); eyes, brows, cheeks are driven by expressions only: the
    # 13 face shapes of the recipes after them (realtime_core.expressions.face_shapes), found in these spellings too.
    speech = head.rig.names[: len(head.rig.names) - head.rig.n_face]
    assert head.kind == "morph" and len(speech) == 22 and head.rig.n_face == 13
    assert all(n.split(".")[-1].startswith(("Jaw", "Mouth")) for n in speech)
    assert not any(n.split(".")[-1].startswith(("Jaw", "Mouth")) for n in head.rig.names[len(speech) :])
    for p in ([0, 0, 0.3, 0], [0.03, 0.05, 0.1, -0.02], [-0.02, -0.1, 0.05, 0.04]):
        np.testing.assert_allclose(head.rig.deformed(np.array(p)), builtin_morph.rig.deformed(np.array(p)), atol=1e-4)


def test_a_character_creator_head_with_split_targets_moves_as_the_arkit_head(tmp_path, builtin_morph):
    """The built-in head's ARKit targets in Character Creator 4's names: its own words for sided targets
    (Mouth_Up_Upper_L) and ARKit's unsided targets split into halves (Mouth_Roll_In_Upper_L/R) or quarters
    (Mouth_Funnel_Up_L ... Down_R) by smooth masks that sum to one. The head moves as the ARKit head does at
    speech poses (the parts together are the whole target); without the CC4 names the upper lip's raise and
    the rolled lips had no target (mouthUpperUp, mouthRollUpper unmatched) and the head moved otherwise."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face import face_frame
    from tests.heads import cc4_targets

    b = load_builtin_head()
    fr = face_frame(b.mesh.vertices.astype(np.float64), mouth_landmarks(b.landmarks))
    cc = cc4_targets(b)
    assert "Mouth_Up_Upper_L" in cc and "Mouth_Funnel_Down_R" in cc and "Jaw_Open" in cc
    mesh = HeadMesh(vertices=b.mesh.vertices, triangles=b.mesh.triangles, name="cc", targets=cc)
    path = tmp_path / "cc4_head.glb"
    path.write_bytes(mesh_glb(mesh))
    head = resolve_head(path)
    assert head.kind == "morph"
    assert {"Mouth_Up_Upper_L", "Mouth_Roll_In_Lower_R", "Mouth_Funnel_Up_L", "Mouth_Pucker_Down_R"} <= set(
        head.rig.names
    )
    for p in ([0, 0, 0.3, 0], [0.03, 0.05, 0.1, -0.02], [-0.02, -0.1, 0.05, 0.04], [0.05, -0.08, 0.0, 0.0]):
        want = builtin_morph.rig.deformed(np.array(p)).astype(np.float64)
        got = head.rig.deformed(np.array(p)).astype(np.float64)
        np.testing.assert_allclose(got, want, atol=2e-4 * fr.iod)
    # Each expression's face shapes in CC4's words: Brow_Raise_Outer_L (browOuterUpLeft), Cheek_Raise_L
    # (cheekSquintLeft) and the inner brow split in halves (Brow_Raise_Inner_L/R). Before, none of these was
    # recognised: on a CC4 head a surprise raised no brow, a sad face no inner brow, a smile no cheek.
    from realtime_core.expressions import EXPRESSIONS

    assert {"Brow_Raise_Outer_L", "Cheek_Raise_R", "Brow_Raise_Inner_L", "Brow_Raise_Inner_R"} <= set(
        head.rig.names[-head.rig.n_face :]
    )
    p = np.array([0.01, 0.02, 0.1, 0.0])
    for k, name in enumerate(EXPRESSIONS):
        alpha = np.zeros(len(EXPRESSIONS))
        alpha[k] = 0.8
        want = builtin_morph.rig.deformed(p, alpha).astype(np.float64)
        got = head.rig.deformed(p, alpha).astype(np.float64)
        moved = np.abs(want - builtin_morph.rig.deformed(p)).max()
        assert moved > 0.02 * fr.iod, name  # the expression moves the face beyond the mouth
        np.testing.assert_allclose(got, want, atol=2e-4 * fr.iod, err_msg=name)


def test_a_viseme_only_head_opens_its_jaw(tmp_path, builtin_morph):
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face import measure_mouth

    b = load_builtin_head()
    vis = {f"viseme_{k}": sum(w * b.targets[a] for a, w in mix.items()) for k, mix in VISEME_ARKIT.items() if mix}
    mesh = HeadMesh(vertices=b.mesh.vertices, triangles=b.mesh.triangles, name="v", targets=vis)
    path = tmp_path / "visemes.glb"
    path.write_bytes(mesh_glb(mesh))
    head = resolve_head(path)
    assert head.kind == "morph" and all(n.startswith("viseme_") for n in head.rig.names)
    lm = mouth_landmarks(b.landmarks)
    p = np.array([0, 0, 0.3, 0])
    got = measure_mouth(b.mesh.vertices, head.rig.deformed(p).astype(float), lm)
    ref = measure_mouth(b.mesh.vertices, builtin_morph.rig.deformed(p).astype(float), lm)
    assert got[2] > 0.6 * ref[2] > 0  # the jaw opens most of the way the ARKit head does
    # No face shapes: an expression reaches such a head through the mouth parameters only, as before.
    assert head.rig.n_face == 0 and head.rig.face_recipe is None
    np.testing.assert_array_equal(head.rig.weights(p, np.ones(4)), head.rig.weights(p))


def test_too_few_mouth_targets_fall_back_and_user_maps_add_names(tmp_path, builtin_morph):
    b = builtin_morph.mesh
    eyes = {k: v for k, v in b.targets.items() if k.startswith("eye")}
    eyes["Key 7"] = b.targets["jawOpen"]  # an unnamed jaw target
    mesh = HeadMesh(vertices=b.vertices, triangles=b.triangles, name="e", targets=eyes)
    path = tmp_path / "eyes.glb"
    path.write_bytes(mesh_glb(mesh))
    assert match_targets(list(eyes)).keys() == {k for k in eyes if k.startswith("eye")}
    from assets.errors import MeshError

    with pytest.raises(MeshError, match=r"eyes.glb"):
        resolve_head(path, mode="morph")
    tmap = tmp_path / "map.json"
    tmap.write_text(json.dumps({"targets": {"Key 7": "jawOpen"}}))
    head = resolve_head(path, mode="morph", target_map=tmap)
    assert "Key 7" in head.rig.names
    w = head.rig.weights(np.array([0, 0, 0.3, 0]))
    assert w[list(head.rig.names).index("Key 7")] > 0.5


def test_morph_head_glb_animates_its_own_targets(builtin_morph):
    pygltflib = require_module("pygltflib")
    params = np.array([[0, 0, 0, 0], [0, 0, 0.3, 0], [0.02, -0.08, 0.1, 0]], float)
    data = head_glb(builtin_morph.rig, builtin_morph.mesh, params, 30.0)
    g = pygltflib.GLTF2().load_from_bytes(data)
    assert g.meshes[0].extras["targetNames"] == list(builtin_morph.rig.names)
    acc = g.accessors[g.animations[0].samplers[0].output]
    view = g.bufferViews[acc.bufferView]
    w = np.frombuffer(g.binary_blob(), "<f4", acc.count, view.byteOffset + (acc.byteOffset or 0)).reshape(3, -1)
    np.testing.assert_allclose(w, builtin_morph.rig.weights(params), atol=1e-6)
    assert w.min() >= 0 and w.max() <= 1


def test_morph_displacements_equal_the_reference_solve_and_a_float64_product(builtin_morph):
    """The per-frame path a server's vertex viewer costs (one compiled keyframe solve, then a
    row-vector product over the (P, n_moving*3) targets) against the numpy reference solve and the
    targets summed in float64, at speech poses from closed to wide open."""
    from realtime_core.face.checks import EXTREME_POSES

    rig = replace(builtin_morph.rig, bound=None)  # the solve at any params, not only within the head's bound
    rng = np.random.default_rng(4)
    poses = np.vstack([np.asarray(EXTREME_POSES, dtype=np.float64), rng.uniform(-0.1, 0.5, (20, 4))])
    x = rig.source(poses)
    ref_w = rig.keymap.weights(x, kernel="numpy")
    assert 0.1 < np.mean((ref_w <= 0) | (ref_w >= 1)) < 0.95  # bounds active: the active set matters
    np.testing.assert_allclose(rig.keymap.weights(x), ref_w, rtol=0, atol=1e-10)
    targets = rig.targets[: len(rig.names) - rig.n_face].astype(np.float64)  # (P, n_moving, 3): the speech targets
    for p, w in zip(poses, ref_w):
        want = np.einsum("p,pvc->vc", w.astype(np.float32).astype(np.float64), targets)
        got = rig.displacements(p)
        assert got.shape == (len(rig.moving), 3) and got.dtype == np.float32
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * max(np.abs(want).max(), 1e-3))


def test_a_viseme_only_head_keeps_its_lips_apart_at_closed_lip_poses(tmp_path):
    # OVR visemes at closed-lip poses with the corners up or the upper lip raised: the least-squares
    # fit took the PP viseme (pressed, rolled lips) and drove the inner lips 0.017 IOD through each
    # other; the reference's lip columns now bound the solve.
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face import face_frame

    b = load_builtin_head()
    vis = {f"viseme_{k}": sum(w * b.targets[a] for a, w in mix.items()) for k, mix in VISEME_ARKIT.items() if mix}
    path = tmp_path / "visemes.glb"
    path.write_bytes(mesh_glb(HeadMesh(vertices=b.mesh.vertices, triangles=b.mesh.triangles, name="v", targets=vis)))
    head = resolve_head(path)
    lm = mouth_landmarks(b.landmarks)
    fr = face_frame(b.mesh.vertices, lm)
    for pose in ((0, 0, 0, -0.103), (0.054, 0, 0, 0), (-0.084, 0.015, 0, -0.079)):
        v = head.rig.deformed(np.array(pose, dtype=float)).astype(float)
        gap = float((v[lm.upper_inner] - v[lm.lower_inner]) @ fr.axes[1]) / fr.iod
        assert gap >= -1e-4, (pose, gap)
        assert head.rig.weights(np.array(pose, dtype=float))[head.rig.names.index("viseme_PP")] > 0.3  # still pressed


def test_the_reference_lip_columns_pair_lip_skin_and_the_solve_keeps_them_from_crossing(tmp_path, builtin_morph):
    # The keyframe solve's reference face (the built-in head) had 2 columns: the inner-lip landmarks and
    # an upper tooth over a lower tooth (parts 2 and 3), so "lips never cross" was partly kept on teeth.
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigging import mouth_landmarks
    from assets.heads.targets import arkit_source, reference_lips
    from realtime_core.blendshapes import ARKIT_NAMES
    from realtime_core.face import face_frame

    b = load_builtin_head()
    lips = reference_lips(b.mesh.vertices, b.mesh.triangles, b.targets["jawOpen"], b.landmarks)
    pairs = np.asarray(lips.pairs)
    lm = mouth_landmarks(b.landmarks)
    # Independent of the rule's own piece search: the asset's part labels (0 = skin) of each pair's
    # vertices are those of the inner-lip landmarks, and the columns reach both halves of the mouth.
    assert b.part[lm.upper_inner] == b.part[lm.lower_inner] == 0
    assert (b.part[pairs] == 0).all(), pairs[(b.part[pairs] != 0).any(axis=1)]
    fr = face_frame(b.mesh.vertices, lm)
    x = (b.mesh.vertices[pairs[:, 0]] - b.mesh.vertices[lm.upper_inner]) @ fr.axes[0] / fr.iod
    assert len(pairs) >= 4 and (x > 0.05).any() and (x < -0.05).any()
    vis = {f"viseme_{k}": sum(w * b.targets[a] for a, w in mix.items()) for k, mix in VISEME_ARKIT.items() if mix}
    path = tmp_path / "visemes.glb"
    path.write_bytes(mesh_glb(HeadMesh(vertices=b.mesh.vertices, triangles=b.mesh.triangles, name="v", targets=vis)))
    v0 = b.mesh.vertices.astype(np.float64)
    ref = np.stack([b.targets[n] for n in ARKIT_NAMES]).astype(np.float64)  # (52, n, 3)
    # Bilabial and pressing poses: closed, /m/, the corners up, the upper lip raised.
    for head in (builtin_morph, resolve_head(path)):
        for pose in ((0, 0, 0, 0), (-0.02, 0, 0, 0), (0, 0, 0, -0.103), (0.054, 0, 0, 0), (-0.084, 0.015, 0, -0.079)):
            p = np.array(pose, dtype=np.float64)
            v = head.rig.deformed(p).astype(np.float64)  # the same mesh as the reference face
            src = v0 + np.einsum("k,knd->nd", arkit_source(p), ref)  # the reference motion itself
            gap = (v[pairs[:, 0]] - v[pairs[:, 1]]) @ lips.axis
            floor = np.minimum(0.0, (src[pairs[:, 0]] - src[pairs[:, 1]]) @ lips.axis)
            assert (gap >= floor - 1e-4).all(), (head.rig.meta["head"], pose, gap.round(4), floor.round(4))


def test_builtin_morph_rig_is_cached_and_read_back_identical(tmp_path, monkeypatch):
    """The built-in head's morph rig is built once per cache (the build solves the keyframe QP at every probe
    and speech pose) and read back afterwards: the read rig gives the built rig's weights and vertices bit for bit."""
    from assets.heads import targets
    from assets.heads.builtin import HEAD_FILE, load_builtin_head
    from assets.heads.cache import cache_dir
    from realtime_core.face.checks import EXTREME_POSES

    load_builtin_head()  # the user's cache holds the cut head (downloaded once); link it, not the morph rig
    (tmp_path / HEAD_FILE).symlink_to(cache_dir() / HEAD_FILE)
    builds = []
    real = targets.morph_rig
    monkeypatch.setattr(targets, "morph_rig", lambda *a, **k: builds.append(1) or real(*a, **k))
    built = builtin_morph_head(tmp_path)
    assert len(builds) == 1 and len(list(tmp_path.glob("builtin_morph_*.npz"))) == 1
    read = builtin_morph_head(tmp_path)
    assert len(builds) == 1  # the second head came from the cache file
    assert read.rig is not built.rig and read.rig.names == built.rig.names and read.rig.meta == built.rig.meta
    poses = np.array([*EXTREME_POSES, (0.0, 0.0, 0.0, 0.0), (0.01, -0.02, 0.13, 0.005)])
    np.testing.assert_array_equal(read.rig.weights(poses), built.rig.weights(poses))
    for p in poses[::4]:
        np.testing.assert_array_equal(read.rig.deformed(p), built.rig.deformed(p))
    # A cache file left unreadable (cut short: a zip without its directory) is built again, not an error.
    path = next(tmp_path.glob("builtin_morph_*.npz"))
    path.write_bytes(path.read_bytes()[:1000])
    again = builtin_morph_head(tmp_path)
    assert len(builds) == 2
    np.testing.assert_array_equal(again.rig.weights(poses), built.rig.weights(poses))


def test_a_head_drives_its_rig_within_the_checked_poses(builtin_morph):
    """A typical-range corner (raised upper lip, full pucker, closed, corners up) crossed the lips 0.012 IOD
    and folded 8 triangles of the built-in head's own targets (the ARKit weights' clip at 1 saturates the
    upper lip's raise and not the shapes that close the lips); a Head's rig gives it its nearest checked pose,
    everywhere it is driven: vertices, morph weights, the exported animation."""
    from assets.heads.head import head_check_inputs
    from realtime_core.face.checks import checked_bound, pose_figures

    corner = np.array([0.06, -0.15, 0.0, -0.1])
    rig = builtin_morph.rig
    held = tuple(tuple(p) for p in rig.meta["checks"]["expressions_held"])
    assert rig.bound is checked_bound(held, rig.meta["checks"]["closure_reach_iod"])
    lm, inputs = head_check_inputs(builtin_morph)
    inputs.pop("joined_pairs")  # the seam check is check_rig's, not a per-pose figure
    free = pose_figures(replace(rig, bound=None), lm, [corner], **inputs)
    # What the bound keeps the head from: a fold (the lips crossed there too, 0.0125 IOD, until the ARKit map's
    # antagonists were netted: no longer).
    assert free.flipped[0] > 0
    held = pose_figures(rig, lm, [corner], **inputs)
    assert held.flipped[0] == 0 and held.interpenetration[0] <= 0.005
    nearest = rig.bound(corner)
    np.testing.assert_array_equal(rig.weights(corner), rig.weights(nearest))
    np.testing.assert_array_equal(rig.deformed(corner), rig.deformed(nearest))
    pygltflib = require_module("pygltflib")
    g = pygltflib.GLTF2().load_from_bytes(head_glb(rig, builtin_morph.mesh, corner[None], 30.0))
    acc = g.accessors[g.animations[0].samplers[0].output]
    view = g.bufferViews[acc.bufferView]
    w = np.frombuffer(g.binary_blob(), "<f4", acc.count, view.byteOffset + (acc.byteOffset or 0))
    np.testing.assert_allclose(w, rig.weights(nearest), atol=1e-6)


def test_a_head_is_bound_to_the_expression_poses_its_checks_say_its_rig_holds(builtin_morph, builtin_rig_file):
    """The hull a head drives within is speech and the expression poses its rig holds (its checks' meta
    ``expressions_held``, measured when its rig is built and kept in the cached file; issue 12): the built-in head's
    Sec. 5 rig holds every one and keeps the full hull; its own targets fold 2 triangles at 2 of them (the checks'
    advisory "flipped under expressions"), which its bound leaves out; a rig whose checks say it holds only the
    poses up to lip_stretch 0.1 gives a full smile on speech the nearest of those instead."""
    from assets.heads.head import Head, head_check_inputs
    from realtime_core.face.checks import EXPRESSION_POSES, checked_bound, pose_figures

    rig, mesh = builtin_rig_file
    assert {tuple(p) for p in rig.meta["checks"]["expressions_held"]} == set(EXPRESSION_POSES)
    reach = rig.meta["checks"]["closure_reach_iod"]  # the lips' gap at rest: its own closure pose's
    assert Head(rig, mesh).rig.bound is checked_bound(None, reach)
    own = builtin_morph.rig
    kept = {tuple(p) for p in own.meta["checks"]["expressions_held"]}
    left = sorted(set(EXPRESSION_POSES) - kept)
    assert kept < set(EXPRESSION_POSES) and not any(own.bound.contains(np.array(left)))
    lm, inputs = head_check_inputs(builtin_morph)
    inputs.pop("joined_pairs")
    free = pose_figures(replace(own, bound=None), lm, left, **inputs)
    assert (free.flipped > 0).all()  # each left out folds there: what the bound keeps the head from
    assert pose_figures(own, lm, left, **inputs).flipped.max() == 0
    held = tuple(p for p in EXPRESSION_POSES if p[1] <= 0.1)
    checks = {**rig.meta.get("checks", {}), "expressions_held": [list(p) for p in held]}
    head = Head(replace(rig, meta={**rig.meta, "checks": checks}, bound=None), mesh)
    assert head.rig.bound is checked_bound(held, reach) and head.rig.bound is not checked_bound(None, reach)
    smile = np.array(max(EXPRESSION_POSES, key=lambda p: p[1]))  # the widest smile, lip_stretch > 0.1
    assert checked_bound().contains(smile) and not head.rig.bound.contains(smile)
    nearest = head.rig.bound(smile)
    assert nearest[1] <= 0.1 + 1e-9
    free = replace(head.rig, bound=None)
    np.testing.assert_allclose(head.rig.displacements(smile), free.displacements(nearest), atol=1e-9)


def test_an_own_target_head_without_landmarks_in_its_file_is_checked_with_the_finder(tmp_path, builtin_morph):
    """The built-in head's targets in a glb of their own carry no landmarks: with a landmark finder the head is checked
    on load and bound like the built-in head (its targets fold at the same 2 expression poses; unchecked, a closed-lip
    smile inside the full hull folded 1 triangle, docs/animation.md "Each head's own bound"); without one it keeps
    every checked pose, as before."""
    from realtime_core.face.checks import checked_bound

    path = _arkit_file(tmp_path, builtin_morph, lambda k: k)
    plain = resolve_head(path)
    assert "checks" not in plain.rig.meta and plain.rig.bound is checked_bound()
    points = builtin_morph.rig.meta["landmarks"]
    head = resolve_head(path, landmark_finder=lambda mesh: points)
    held = {tuple(p) for p in head.rig.meta["checks"]["expressions_held"]}
    assert held == {tuple(p) for p in builtin_morph.rig.meta["checks"]["expressions_held"]}
    assert head.rig.bound is builtin_morph.rig.bound and head.rig.bound is not checked_bound()


def test_a_retargeted_head_drives_its_rig_within_the_checked_poses(builtin_rig_file):
    """The built-in head's Sec. 5 rig folded 14 triangles at the typical ranges' corner (-0.05, -0.15, 0.45,
    -0.0625) (docs/animation.md, "Sweep"); as a Head it gives the nearest checked pose there, in its vertex
    deltas and in the exported animation's parameter curves (whose unit targets stay the rig's linear field)."""
    from assets.heads.glb import rig_targets
    from assets.heads.head import Head, head_check_inputs
    from realtime_core.face.checks import checked_bound, pose_figures

    head = Head(*builtin_rig_file)
    corner = np.array([-0.05, -0.15, 0.45, -0.0625])
    lm, inputs = head_check_inputs(head)
    inputs.pop("joined_pairs")  # the seam check is check_rig's, not a per-pose figure
    free = replace(head.rig, bound=None)
    assert pose_figures(free, lm, [corner], **inputs).flipped[0] > 0
    assert pose_figures(head.rig, lm, [corner], **inputs).flipped[0] == 0
    nearest = checked_bound(None, head.rig.meta["checks"]["closure_reach_iod"])(corner)
    np.testing.assert_array_equal(head.rig.displacements(corner), free.displacements(nearest))
    np.testing.assert_allclose(head.rig.bounded(corner[None]), nearest[None])
    e = np.zeros(4, dtype=np.float32)
    e[3] = 1.0  # a unit pose, far outside the bound: the exported target is the linear field's column
    np.testing.assert_allclose(
        rig_targets(head.rig)[3, head.rig.moving], free.displacements(e) - free.contact_push(e), atol=1e-6
    )


def test_an_own_target_head_modelled_with_its_lips_apart_rests_with_them_together(tmp_path, builtin_morph):
    """The built-in head with 0.3 of its jawOpen baked into the mesh (its lips modelled about 0.18 IOD apart) and its
    targets kept: no fit of them goes below its neutral, so every /m b p/ and silence (params 0) left the lips as far
    apart as modelled. It now rests at jawOpen -0.3, which brings its inner lips to the built-in head's own gap
    (the targets are linear): the built-in head's face at every pose, the head as modelled still the rig's neutral,
    its checks passing with the lips 0.007 IOD apart at rest. The built-in head's own targets in a file, lips within
    the closure limit, rest as modelled. The rest is read back from the cache."""
    m = builtin_morph.mesh
    v0 = np.asarray(builtin_morph.rig.neutral, dtype=np.float64)
    marks = builtin_morph.rig.meta["landmarks"]
    at = {k: int(np.argmin(np.linalg.norm(v0 - np.asarray(p), axis=1))) for k, p in marks.items()}
    parted_v = m.vertices + 0.3 * m.targets["jawOpen"]
    path = tmp_path / "parted.glb"
    path.write_bytes(
        mesh_glb(HeadMesh(vertices=parted_v, triangles=m.triangles, colors=m.colors, name="p", targets=dict(m.targets)))
    )
    points = {k: parted_v[i].tolist() for k, i in at.items()}
    head = resolve_head(path, landmark_finder=lambda mesh: points, cache=tmp_path)
    assert head.kind == "morph" and list(head.rig.meta["rest_weights"]) == ["jawOpen"]
    assert head.rig.meta["rest_weights"]["jawOpen"] == pytest.approx(-0.3, abs=0.005)
    n = len(m.vertices)
    np.testing.assert_array_equal(head.rig.neutral[:n], parted_v.astype(np.float32))
    up = np.asarray(v0[at["upper_lip"]] - v0[at["chin"]])  # any upward axis: the gaps are compared, not measured

    def gap(verts: np.ndarray) -> float:
        return float((verts[at["upper_inner"]] - verts[at["lower_inner"]]) @ up)

    unrested = replace(head.rig, rest=None)
    assert gap(unrested.deformed(np.zeros(4))) > 10 * gap(builtin_morph.rig.deformed(np.zeros(4))) > 0
    # Within 1e-3 head units (0.002 IOD): the rest (-0.3016) meets the reference gap as measured at the built-in
    # head's own landmark vertices, a vertex or so from the points the finder gave.
    for p in ([0, 0, 0, 0], [-0.02, 0, 0, 0], [0, 0.02, 0.35, 0], [0.03, 0.05, 0.1, -0.02]):
        np.testing.assert_allclose(
            head.rig.deformed(np.array(p))[:n], builtin_morph.rig.deformed(np.array(p))[:n], atol=1e-3
        )
    checks = head.rig.meta["checks"]
    assert checks["passed"] and checks["closure_gap_iod"] <= 0.01 and checks["bilabial_gap_iod"] <= 0.01
    own = builtin_morph.rig.meta["checks"]["closure_reach_iod"]  # the built-in head's lips at rest: 0.007 IOD
    assert checks["closure_reach_iod"] == pytest.approx(own, abs=1e-3)
    again = resolve_head(path, landmark_finder=lambda mesh: points, cache=tmp_path)
    np.testing.assert_array_equal(again.rig.rest, head.rig.rest)
    # Lips within the limit: no rest.
    plain = resolve_head(_arkit_file(tmp_path, builtin_morph, lambda k: k), landmark_finder=lambda mesh: marks)
    assert plain.rig.rest is None and "rest_weights" not in plain.rig.meta


def test_the_builtin_heads_own_targets_in_a_file_rest_as_modelled_under_automatic_landmarks(tmp_path, builtin_morph):
    """The built-in head's targets in a glb, loaded as `--head x.glb` loads it (the automatic landmarks): it rested at
    jawOpen -0.007. Those landmarks tilt the face's up axis 10.3 degrees from the shipped ones, and its lower inner
    lip lies behind the upper, so its 0.0070 IOD lips read 0.0111, over the 0.01 limit. Its rest is its own: no rest
    weights, every target 0 at params 0, the face at params 0 its neutral, its checks passing."""
    from clients.render.landmarks import find_landmarks

    path = _arkit_file(tmp_path, builtin_morph, lambda k: k)
    head = resolve_head(path, landmark_finder=find_landmarks, cache=tmp_path / "cache")
    assert head.kind == "morph" and head.rig.rest is None and "rest_weights" not in head.rig.meta
    np.testing.assert_array_equal(head.rig.weights(np.zeros((1, 4)))[0], 0.0)
    np.testing.assert_array_equal(head.rig.deformed(np.zeros(4)), head.rig.neutral)
    assert head.rig.meta["checks"]["passed"]


def test_an_expression_moves_the_heads_own_face_shapes_and_leaves_the_speech_weights(builtin_morph):
    """Through the four parameters alone an expression moved only the mouth: `render --expression surprise` on the
    built-in head showed no raised brows and no wide eyes, and the browser's expression buttons hardly changed the
    face. The head's own cheek, eye and brow targets now take each recipe's face shapes: the vertices move by exactly
    the recipe's weights times the mesh's own targets (read from the file, not from the rig), and the speech
    targets' weights are those without the expression, bit for bit."""
    from realtime_core.expressions import EXPRESSIONS, face_shapes

    rig, mesh = builtin_morph.rig, builtin_morph.mesh
    assert rig.n_face > 0 and set(rig.meta["face_shapes"]) == set(rig.names[-rig.n_face :])
    p = np.array([0.01, 0.02, 0.2, 0.0])
    w0 = rig.weights(p)
    assert not w0[-rig.n_face :].any()  # no expression: the face shapes rest
    for k, name in enumerate(EXPRESSIONS):
        alpha = np.zeros(len(EXPRESSIONS))
        alpha[k] = 0.8
        w = rig.weights(p, alpha)
        np.testing.assert_array_equal(w[: -rig.n_face], w0[: -rig.n_face])
        moved = rig.deformed(p, alpha).astype(np.float64) - rig.deformed(p).astype(np.float64)
        want = sum(0.8 * wt * np.asarray(mesh.targets[n], dtype=np.float64) for n, wt in face_shapes(name).items())
        np.testing.assert_allclose(moved, want, atol=1e-5)
        assert np.abs(want).max() > 1e-3, name  # each expression moves the face beyond the mouth
    # intensities over several expressions at once: clipped to a target's [0, 1]
    assert rig.weights(p, np.ones(len(EXPRESSIONS)))[-rig.n_face :].max() <= 1.0


def test_the_face_shapes_survive_the_rig_file_and_reach_the_glb(tmp_path, builtin_morph):
    pygltflib = require_module("pygltflib")
    from assets.heads.targets import morph_rig_arrays, morph_rig_from_arrays
    from realtime_core.expressions import EXPRESSIONS

    rig = builtin_morph.rig
    back = morph_rig_from_arrays(morph_rig_arrays(rig), rig.neutral, rig.triangles)
    np.testing.assert_array_equal(back.face_recipe, rig.face_recipe)
    alpha = np.zeros((2, len(EXPRESSIONS)))
    alpha[1, EXPRESSIONS.index("surprise")] = 1.0
    params = np.array([[0, 0, 0.1, 0], [0, 0, 0.1, 0]], float)
    g = pygltflib.GLTF2().load_from_bytes(head_glb(rig, builtin_morph.mesh, params, 30.0, expression=alpha))
    acc = g.accessors[g.animations[0].samplers[0].output]
    view = g.bufferViews[acc.bufferView]
    w = np.frombuffer(g.binary_blob(), "<f4", acc.count, view.byteOffset + (acc.byteOffset or 0)).reshape(2, -1)
    names = g.meshes[0].extras["targetNames"]
    brow = names.index(next(n for n in names if canonical_name(n) == "browInnerUp"))
    assert w[0, brow] == 0 and w[1, brow] == pytest.approx(0.7)


def test_a_frame_without_an_expression_skips_the_face_shapes_bit_for_bit(builtin_morph):
    """The face shapes add 13 targets and 699 moving vertices to the built-in head: a frame without an expression
    multiplies only the speech targets (MorphRig.active), with exactly the displacements of the whole product."""
    from realtime_core.face.compiled import morph_displacements

    rig = builtin_morph.rig
    w = rig.weights(np.random.default_rng(5).uniform(-0.05, 0.3, (6, 4)))
    trimmed, rows = rig.active(w)
    assert trimmed.shape[1] == rows.shape[0] == len(rig.names) - rig.n_face
    whole = morph_displacements(w, rig.flat_targets, np.empty((6, rig.flat_targets.shape[1]), dtype=np.float32))
    assert rig.displacements_rows(w).tobytes() == whole.tobytes()
    assert rig.displacements_rows(w, kernel="numpy").shape == whole.shape


def test_a_head_without_landmarks_is_framed_on_its_speech_targets_not_its_face_shapes(tmp_path, builtin_morph):
    """A head driven by its own targets with no landmarks is framed on the vertices its targets move most (lips, jaw,
    chin). Since the face shapes joined the rig, brows and eyes counted too: the box reached the brows and an ARKit
    glb, a Character Creator or a VRM head with emotion expressions was drawn higher, its chin cut at the picture's
    bottom edge. The same head without its face-shape targets must be framed identically (the same pixels)."""
    from clients.render.renderer import RenderConfig, renderer_for_rig
    from realtime_core.expressions import EXPRESSIONS, face_shapes

    full = resolve_head(_arkit_file(tmp_path, builtin_morph, lambda n: n))
    assert full.rig.n_face == 13 and not full.rig.meta.get("landmarks")
    shapes = {k for e in EXPRESSIONS for k in face_shapes(e)}
    (tmp_path / "bare").mkdir()
    bare_mesh = replace(builtin_morph.mesh, targets={k: v for k, v in full.mesh.targets.items() if k not in shapes})
    bare = resolve_head(_arkit_file(tmp_path / "bare", SimpleNamespace(mesh=bare_mesh), lambda n: n))
    assert bare.rig.n_face == 0
    cfg = RenderConfig(width=160, height=120, samples=0)
    shots = []
    for head in (full, bare):
        with renderer_for_rig(head.rig, head.mesh, cfg) as r:
            shots.append(r.render(head.rig.deformed(np.zeros(4))))
    assert np.array_equal(shots[0], shots[1])


def test_a_target_map_names_a_face_shape_an_expression_then_drives(tmp_path, builtin_morph):
    """`--target-map` naming a brow target (`{"BrowsUp": "browInnerUp"}`) mapped it for speech but not for an
    expression: a surprise left the head's own brows still. A map entry naming one face shape now drives it (at the
    recipe's weight over the map's: `{"Half": {"browInnerUp": 0.5}}` is driven at twice the weight)."""
    from realtime_core.expressions import EXPRESSIONS, face_shapes

    b = builtin_morph.mesh
    targets = {k: v for k, v in b.targets.items() if k.startswith(("jaw", "mouth"))}
    targets["BrowsUp"] = b.targets["browInnerUp"]
    targets["HalfWide"] = 0.5 * b.targets["eyeWideLeft"]
    path = tmp_path / "mapped.glb"
    path.write_bytes(mesh_glb(HeadMesh(vertices=b.vertices, triangles=b.triangles, name="m", targets=targets)))
    tmap = tmp_path / "map.json"
    tmap.write_text(json.dumps({"targets": {"BrowsUp": "browInnerUp", "HalfWide": {"eyeWideLeft": 0.5}}}))
    without = resolve_head(path, mode="morph", landmark_finder=lambda mesh: builtin_morph.rig.meta["landmarks"])
    assert "BrowsUp" not in without.rig.names  # not an ARKit spelling: only the map says what it is
    head = resolve_head(
        path, mode="morph", target_map=tmap, landmark_finder=lambda mesh: builtin_morph.rig.meta["landmarks"]
    )
    names = list(head.rig.names)
    assert head.rig.meta["face_shapes"] == {"BrowsUp": "browInnerUp", "HalfWide": "eyeWideLeft"}
    alpha = np.zeros(len(EXPRESSIONS))
    alpha[EXPRESSIONS.index("surprise")] = 1.0
    w = head.rig.weights(np.zeros(4), alpha)
    want = face_shapes("surprise")
    assert w[names.index("BrowsUp")] == pytest.approx(want["browInnerUp"])
    assert w[names.index("HalfWide")] == pytest.approx(min(1.0, 2 * want["eyeWideLeft"]))
