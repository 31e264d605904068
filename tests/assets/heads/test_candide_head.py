"""Candide-3 as a head: driven through its own animation units (no retarget), the four mouth
parameters it shows equal the ones asked for, it passes the rig checks, faces the viewer and exports."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from assets.heads.head import head_checks, resolve_head
from realtime_core.face.candide import candide3_mouth_landmarks
from realtime_core.face.model import measure_mouth

FILES = ("candide3-3.1.6.wfm", "candide3-uv-variant.wfm")


@pytest.mark.parametrize("name", FILES)
def test_candide_head_shows_the_parameters_asked_for(shared_data, name):
    head = resolve_head(shared_data / "candide3" / name)
    rig = replace(head.rig, bound=None)  # the units' own answer at any params (a Head bounds them, test_morph_heads)
    assert head.kind == "morph" and head.mesh.part_names == ("head", "mouth cavity")
    assert int((head.mesh.part == 0).sum()) == 113  # the wireframe, then the (still) mouth cavity
    # One of its own units per parameter: lip raiser, stretcher, jaw drop, corner depressor.
    for n, key in zip(rig.names, ("upper lip raiser", "lip stretcher", "jaw drop", "lip corner depressor")):
        assert key in n.lower()
    lm = candide3_mouth_landmarks()
    rng = np.random.default_rng(0)
    checked = 0
    for p in [np.array([0.0, 0.0, 0.3, 0.0]), *rng.uniform([-0.02, -0.1, 0, -0.02], [0.03, 0.08, 0.3, 0.03], (8, 4))]:
        w = rig.weights(p)
        if np.abs(w).max() >= 1:  # the AUs' range is [-1, 1]: only poses inside it are reproduced exactly
            continue
        # Measured on the deformed wireframe, independently of the calibration that built the weights.
        np.testing.assert_allclose(measure_mouth(rig.neutral, rig.deformed(p), lm), p, atol=1e-5)
        checked += 1
    assert checked >= 5
    assert np.abs(rig.displacements(np.zeros(4))).max() == 0  # silence: no motion
    assert head_checks(head).passed


@pytest.mark.system
def test_candide_head_faces_the_viewer_and_exports(shared_data, tmp_path):
    """Rendered (the file mixes triangle windings: every triangle must face the camera, no dark back
    face) and exported as an animated glb of its own animation units."""
    from assets.heads.glb import head_glb
    from assets.heads.mesh import load_mesh
    from clients.render.renderer import RenderConfig, renderer_for_rig

    head = resolve_head(shared_data / "candide3" / FILES[0])
    with renderer_for_rig(head.rig, head.mesh, RenderConfig(width=200, height=200, samples=0)) as r:
        img = r.render().astype(float)
    background = np.median(np.concatenate([img[:5].reshape(-1, 3), img[-5:].reshape(-1, 3)]), axis=0)
    face = np.abs(img - background).sum(axis=2) > 30
    assert face.mean() > 0.15
    assert np.mean(img[face].sum(axis=1) < 120) < 0.02  # back faces are drawn near-black
    params = np.array([[0, 0, 0, 0], [0, 0.02, 0.35, 0], [0, -0.1, 0.08, 0]], float)
    path = tmp_path / "candide.glb"
    path.write_bytes(head_glb(head.rig, head.mesh, params, 30.0))
    back = load_mesh(path)
    assert sorted(back.targets) == sorted(head.rig.names)


@pytest.mark.parametrize("name", FILES)
def test_candide_head_never_presses_its_lips_through_each_other(shared_data, name):
    """Candide-3's lips touch at rest (gap 0). The shared closure reach (mouth_open down to -0.02 IOD, made for heads
    driven by their own targets whose lips are modelled apart) let a pose in its hull press them 0.0144 IOD through
    each other; the head's own reach (its checks' closure pose) keeps mouth_open from going below where they meet."""
    from assets.heads.head import head_check_inputs
    from realtime_core.face.checks import CLOSURE_REACH, checked_bound, pose_figures

    head = resolve_head(shared_data / "candide3" / name)
    reach = head.rig.meta["checks"]["closure_reach_iod"]
    assert reach == pytest.approx(0.0, abs=1e-6)
    assert head.rig.bound is checked_bound(tuple(map(tuple, head.rig.meta["checks"]["expressions_held"])), reach)
    pose = np.array([-0.0042, 0.0134, -0.0144, 0.0053])  # the hull pose where they crossed (docs/animation.md)
    assert checked_bound(None, CLOSURE_REACH).contains(pose) and not head.rig.bound.contains(pose)
    assert head.rig.bound(pose)[2] >= -1e-6  # mouth_open no further below 0 than the lips' gap at rest
    lm, inputs = head_check_inputs(head)
    inputs.pop("joined_pairs")  # the seam check is check_rig's, not a per-pose figure
    shared = pose_figures(replace(head.rig, bound=checked_bound(None, CLOSURE_REACH)), lm, [pose], **inputs)
    own = pose_figures(head.rig, lm, [pose], **inputs)
    assert shared.interpenetration[0] > 0.01 and own.interpenetration[0] <= 1e-6
