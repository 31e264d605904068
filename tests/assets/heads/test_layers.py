"""A layer on the skin (a beard shell) moves with the skin beneath it, each lip's side with its own lip."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
from trimesh.triangles import closest_point, points_to_barycentric

from assets.heads.layers import LAYER_REACH, layer_vertices, with_layers, without_layers
from assets.heads.mesh import HeadMesh
from assets.heads.rigging import cut_mouth
from realtime_core.face.rig import with_rest_pose
from tests.grids import grid_triangles

NX, NY, DX, DY = 13, 9, 0.1, 0.05  # IOD 1
OFF = 0.02  # the layer this far in front of the skin
JUT = 0.06  # the upper lip's first row this far forward: its underside overhangs the lower lip


def _lips():
    """Closed lips cut along their contact row y = 0, the upper lip's first row JUT forward (an overhanging upper lip,
    as Lee Perry-Smith's), the rest flat (z = 0): (vertices, triangles, lower copies, their upper twins, landmarks)."""
    xs = (np.arange(NX) - NX // 2) * DX
    ys = (np.arange(NY) - NY // 2) * DY
    v = np.array([[x, y, JUT if j == NY // 2 + 1 else 0.0] for j, y in enumerate(ys) for x in xs])
    at = np.arange(NX * NY).reshape(NY, NX)
    left, right, mid = int(at[NY // 2, -1]), int(at[NY // 2, 0]), int(at[NY // 2, NX // 2])
    v2, t2, _, origin = cut_mouth(v, grid_triangles(NY, NX), left, right, np.array([0.0, 1.0, 0.0]), through=mid)
    copies = np.arange(len(v), len(v2))
    lm = {"corner_left": left, "corner_right": right, "nose_tip": int(at[-1, NX // 2])}
    return v2, t2, copies, origin[copies], lm


def _layer_points() -> np.ndarray:
    """(k, 3) layer vertices OFF in front of the flat skin over the middle of the mouth: rows far below and above the
    contact line and rows just below it, where the upper lip's jutting underside is nearer than the lower lip."""
    xs = (np.arange(NX) - NX // 2)[3:-3] * DX
    return np.array([[x, y, OFF] for x in xs for y in (-2.5 * DY, -0.2 * DY, -0.1 * DY, 2.5 * DY)])


def _rig(builtin_rig_file, v: np.ndarray, t: np.ndarray, lower: np.ndarray, layer: np.ndarray):
    """A rig of the skin ``v``/``t`` and the separate ``layer`` points after it whose mouth_open drops each skin
    vertex of the lower lip's side (``lower`` (n,) bool) by 1 - x^2 (IOD per IOD) and moves the rest not at all (the
    layer too: no control point lies on it)."""
    base = builtin_rig_file[0]
    n_s = base.simple.n_vertices
    moving = np.flatnonzero(lower)
    drop = 1.0 - v[moving, 0] ** 2
    matrix = sp.csr_matrix((-drop, (3 * np.arange(len(moving)) + 1, np.ones(len(moving)))), (3 * len(moving), 3 * n_s))
    basis = np.zeros((3 * n_s, 4))
    basis[1, 2] = 1.0  # the simple face's first vertex's y: mouth_open
    neutral = np.vstack([v, layer])
    return replace(
        base,
        neutral=neutral.astype(np.float32),
        triangles=np.asarray(t, dtype=np.int32),
        moving=moving.astype(np.int64),
        matrix=matrix,
        basis=basis,
        meta={},
        contact=np.zeros((0, 2), dtype=np.int64),
        contact_spread=None,
        bound=None,
    )


@pytest.mark.parametrize("rest", [0.0, 0.1])
def test_a_layer_moves_as_the_skin_beneath_it_on_its_own_lips_side(builtin_rig_file, rest):
    """``rest``: the rig rests at mouth_open ``rest`` (``with_rest_pose``, lips modelled apart): the layer rests with
    its skin there too, so at every pose it lies where the skin beneath it does."""
    v, t, copies, originals, lm = _lips()
    lower = (v[:, 1] < -1e-9) | np.isin(np.arange(len(v)), copies)
    layer = _layer_points()
    rig = _rig(builtin_rig_file, v, t, lower, layer)
    if rest:
        rig = with_rest_pose(rig, np.array([0.0, 0.0, rest, 0.0]))
    n = len(v)
    ids = n + np.arange(len(layer))
    part = np.r_[np.zeros(n, dtype=np.int64), np.ones(len(layer), dtype=np.int64)]
    out = with_layers(rig, ids, part, ("face", "beard"), lm, np.eye(3), 1.0, seam=np.column_stack([originals, copies]))
    pose = np.array([0.0, 0.0, 0.3, 0.0])
    moved = out.deformed(pose).astype(np.float64)
    skin = moved[:n]
    assert np.array_equal(skin, rig.deformed(pose)[:n])  # the skin as it was
    # Independently: each layer vertex's foot on its own lip's faces (below the mouth line the lower's), by brute
    # force over those faces, and that foot's motion with the skin.
    t = np.asarray(t, dtype=np.int64)
    for below in (True, False):
        faces = t[lower[t].all(axis=1)] if below else t[~lower[t].all(axis=1) & ~lower[t].any(axis=1)]
        who = np.flatnonzero((layer[:, 1] < 0) == below)
        tri = v[faces]
        for i in who:
            foot = closest_point(tri, np.repeat(layer[i : i + 1], len(faces), axis=0))
            k = int(np.argmin(np.linalg.norm(foot - layer[i], axis=1)))
            w = points_to_barycentric(tri[k : k + 1], foot[k : k + 1])[0]
            expected = w @ skin[faces[k]] - foot[k]
            np.testing.assert_allclose(moved[ids[i]] - layer[i], expected, atol=1e-6)
    # The rows just below the contact line lie nearer the upper lip's jutting underside than the lower lip (a carry
    # blind to the sides would keep them still while the lower lip drops): they drop with the lower lip.
    near = (layer[:, 1] < 0) & (layer[:, 1] > -DY)
    upper_faces = v[t[~lower[t].any(axis=1)]]
    d_up = [
        np.linalg.norm(closest_point(upper_faces, np.tile(p, (len(upper_faces), 1))) - p, axis=1).min() for p in layer
    ]
    assert np.array(d_up)[near].min() < OFF  # the check above can fail
    assert np.all(moved[ids[near], 1] - layer[near, 1] < -0.1)


def test_a_part_on_the_skin_is_a_layer_and_one_apart_from_it_is_not():
    v, t, _, _, _ = _lips()
    n = len(v)
    flat = np.flatnonzero(np.abs(v[:n, 2]) < 1e-12)
    beard = v[flat[:20]] + [0.0, 0.0, 0.5 * LAYER_REACH]
    away = v[flat[:20]] + [0.0, 0.0, 3.0 * LAYER_REACH]  # a teeth row or a body: not on the skin
    tri = np.array([[0, 1, 2]])
    verts = np.vstack([v, beard, away])
    tris = np.vstack([t, tri + n, tri + n + 20])
    part = np.r_[np.zeros(n), np.ones(20), np.full(20, 2)].astype(np.int64)
    got = layer_vertices(verts, tris, part, ("face", "beard", "thing"), 0, 1.0)
    assert got[n : n + 20].all() and not got[:n].any() and not got[n + 20 :].any()
    named = layer_vertices(verts, tris, part, ("face", "eyelashes", "thing"), 0, 1.0)  # "lash": an eye part
    assert not named.any()
    brows = layer_vertices(verts, tris, part, ("face", "Eyebrows", "thing"), 0, 1.0)  # brows are skin: a layer
    np.testing.assert_array_equal(brows, got)
    # A dense scan's decimated copy is made without its layers (their decimated vertices took the skin's part).
    mesh = HeadMesh(vertices=verts, triangles=tris, part=part.astype(np.int16), part_names=("face", "beard", "thing"))
    bare = without_layers(mesh, 0, 1.0)
    np.testing.assert_array_equal(bare.vertices, verts[~got])
    assert (np.bincount(bare.part) == [n, 0, 20]).all() and len(bare.triangles) == len(tris) - 1
    np.testing.assert_array_equal(bare.vertices[bare.triangles[-1]], away[:3])
