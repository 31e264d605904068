"""Which way a head is wound, as a camera in front sees it (:func:`clients.render.landmarks.facing_viewer`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import trimesh

from assets.heads.mesh import HeadMesh
from clients.render.landmarks import _axes, facing_viewer

FRONT = _axes(np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))


def _outward(v: np.ndarray, t: np.ndarray) -> bool:
    """Independent of the rule: a closed mesh is wound outwards when its signed volume is positive."""
    return bool(np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() > 0)


def test_a_closed_head_wound_either_way_faces_the_camera_outwards():
    """An ellipsoid (a closed head) wound outwards is left alone; wound inwards it is reversed; from the
    side or from above too (any view of a closed surface sees its outside)."""
    s = trimesh.creation.icosphere(subdivisions=3)
    v = np.asarray(s.vertices) * [0.8, 1.0, 0.9]
    t = np.asarray(s.faces, dtype=np.int64)
    if not _outward(v, t):
        t = t[:, ::-1]
    head = HeadMesh(vertices=v, triangles=t, name="ellipsoid")
    inwards = replace(head, triangles=np.ascontiguousarray(t[:, ::-1]))
    assert not _outward(v, inwards.triangles)
    for axes in (FRONT, _axes(np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])), np.roll(FRONT, 1, axis=0)):
        assert facing_viewer(head, axes) is head
        np.testing.assert_array_equal(facing_viewer(inwards, axes).triangles, t)


def test_a_hollow_head_is_judged_by_the_surface_in_front():
    """A hollow head seen from the front: the face (an open shell bulging towards the camera) and behind it,
    within its outline, the back of the head, whose outside faces away from the camera. Wound outwards it
    stays; wound inwards (the face's back towards the camera, the back of the head's inside) it is reversed.
    Seen from behind, the back of the head is in front and decides the same way."""
    xs = np.linspace(-1.0, 1.0, 9)
    n = len(xs)
    tri = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            tri += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]  # anticlockwise seen from +z
    t1 = np.array(tri)
    face = np.array([[x, y, 1.0 - 0.3 * (x * x + y * y)] for y in xs for x in xs])
    back = np.array([[0.8 * x, 0.8 * y, -1.0 - 0.2 * (x * x + y * y)] for y in xs for x in xs])
    v = np.vstack([face, back])
    head = HeadMesh(vertices=v, triangles=np.vstack([t1, (t1 + n * n)[:, ::-1]]), name="hollow head")
    a, b, c = (v[head.triangles[:, k]] for k in range(3))
    z = np.cross(b - a, c - a)[:, 2]
    assert (z[: len(t1)] > 0).all() and (z[len(t1) :] < 0).all()  # outwards: the face +z, the back -z
    inwards = replace(head, triangles=np.ascontiguousarray(head.triangles[:, ::-1]))
    behind = _axes(np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, -1.0]))
    for axes in (FRONT, behind):
        assert facing_viewer(head, axes) is head
        np.testing.assert_array_equal(facing_viewer(inwards, axes).triangles, head.triangles)
