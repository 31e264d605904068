"""Casting found landmark pixels back onto the mesh (:mod:`clients.render.landmarks`), on a synthetic mesh
and camera (no render, no MediaPipe)."""

from __future__ import annotations

import numpy as np

from assets.heads.mesh import HeadMesh
from clients.render.landmarks import INNER_LIP_DEPTH, SIZE, _cast, _onto_lips


def _quad(x0: float, x1: float, y0: float, y1: float, z: float, base: int) -> tuple[np.ndarray, np.ndarray]:
    v = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]]) + base


def _pixel(p: np.ndarray, mvp: np.ndarray) -> np.ndarray:
    c = mvp @ np.r_[p, 1.0]
    return np.array([(c[0] / c[3] + 1) / 2 * SIZE, (1 - c[1] / c[3]) / 2 * SIZE])


def test_an_inner_lip_point_cast_through_a_slit_between_the_lips_moves_onto_the_lip():
    """A low-poly head whose closed lips meet in a slit (Lee Perry-Smith at ~4,000 triangles): the found
    inner-lip pixel lies in the slit, and the front-most surface under it is far behind the lips (there: 1
    IOD deep, inside the head; here a back wall). The point moves to the first lip surface met from it
    towards the outer lip midpoint; a point on the lip is left where it is."""
    upper, tu = _quad(-0.3, 0.3, 0.05, 0.4, 0.0, 0)
    lower, tl = _quad(-0.3, 0.3, -0.4, -0.05, 0.0, 4)
    wall, tw = _quad(-2.0, 2.0, -2.0, 2.0, -1.0, 8)
    mesh = HeadMesh(vertices=np.vstack([upper, lower, wall]), triangles=np.vstack([tu, tl, tw]), name="slit")
    # A camera on +z looking back (w = 2 - z: nearer surfaces have smaller w).
    mvp = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, -1.0, 2.0]])
    on_face = {
        "eye_outer_left": [0.6, 1.0, 0.0],
        "eye_inner_left": [0.4, 1.0, 0.0],
        "eye_outer_right": [-0.6, 1.0, 0.0],
        "eye_inner_right": [-0.4, 1.0, 0.0],  # IOD 1
        "upper_lip": [0.0, 0.3, 0.0],
        "lower_lip": [0.0, -0.3, 0.0],
    }
    pixels = {k: _pixel(np.array(p), mvp) for k, p in on_face.items()}
    pixels["upper_inner"] = _pixel(np.array([0.0, 0.01, 0.0]), mvp)  # in the slit
    pixels["lower_inner"] = _pixel(np.array([0.05, -0.1, 0.0]), mvp)  # on the lower lip
    names = list(pixels)
    cast = _cast(mesh, mvp, np.array([pixels[k] for k in names]), SIZE)
    points = dict(zip(names, cast))
    assert points["upper_inner"][2] == -1.0  # through the slit onto the wall
    assert INNER_LIP_DEPTH < 1.0
    got = _onto_lips(mesh, mvp, pixels, points, np.array([0.0, 0.0, 1.0]))
    assert got["upper_inner"][2] == 0.0 and 0.05 <= got["upper_inner"][1] < 0.05 + 0.3 / 32 + 1e-9
    assert abs(got["upper_inner"][0]) < 1e-9  # on the segment to the outer lip point
    np.testing.assert_array_equal(got["lower_inner"], points["lower_inner"])
    assert all(np.array_equal(got[k], points[k]) for k in on_face)
