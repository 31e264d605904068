"""Casting found landmark pixels back onto the mesh (:mod:`clients.render.landmarks`), on a synthetic mesh
and camera (no render, no MediaPipe)."""

from __future__ import annotations

import numpy as np

from assets.heads.mesh import HeadMesh
from clients.render.landmarks import (
    CORNER_DEPTH,
    CORNER_RAY_REACH,
    INNER_LIP_DEPTH,
    LOWER_LIP_FLAT,
    SIZE,
    SLIT_WALL_STEP,
    _cast,
    _crease_vertices,
    _face_pieces,
    _into_corner_crease,
    _lower_lip_front,
    _onto_lips,
    _refined,
)

# A camera on +z looking back (w = 2 - z: nearer surfaces have smaller w).
MVP = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, -1.0, 2.0]])


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
    mesh, pixels, points = _slit()
    assert points["upper_inner"][2] == -1.0  # through the slit onto the wall
    assert INNER_LIP_DEPTH < 1.0
    got = _onto_lips(mesh, MVP, pixels, points, np.array([0.0, 0.0, 1.0]), _face_pieces(mesh))
    assert got["upper_inner"][2] == 0.0 and 0.05 <= got["upper_inner"][1] < 0.05 + 0.3 / 32 + 1e-9
    assert abs(got["upper_inner"][0]) < 1e-9  # on the segment to the outer lip point
    np.testing.assert_array_equal(got["lower_inner"], points["lower_inner"])
    assert all(np.array_equal(got[k], points[k]) for k in pixels if not k.endswith("_inner"))  # corners on the lip


def _slit(
    wall_depth: float | None = None, tooth_depth: float | None = None
) -> tuple[HeadMesh, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Closed lips meeting in a slit (y -0.05 to 0.05) in front of a back wall 1 behind them; with ``wall_depth``, the
    upper lip's wall in the slit too: a strip that far behind the lips from y = 0.02 up to the upper lip (y = 0.05),
    seen through the slit above the upper inner-lip pixel (y = 0.01), which still shows the back wall, and joined to
    the upper lip by a face seen edge-on (the lip's inner surface: one piece with the lip). With ``tooth_depth``, a
    tooth that far behind the lips filling the slit (y -0.05 to 0.05), a piece of its own. The corners lie on the
    lips. Returns (mesh, pixels, points as cast)."""
    upper, tu = _quad(-0.3, 0.3, 0.05, 0.4, 0.0, 0)
    lower, tl = _quad(-0.3, 0.3, -0.4, -0.05, 0.0, 4)
    wall, tw = _quad(-2.0, 2.0, -2.0, 2.0, -1.0, 8)
    parts = [(upper, tu), (lower, tl), (wall, tw)]
    if wall_depth is not None:
        parts.append(_quad(-0.3, 0.3, 0.02, 0.05, -wall_depth, 12))
        # From the lip's lower edge (y 0.05, z 0) back to the strip's top edge (y 0.05, z -wall_depth).
        joint = np.array([[-0.3, 0.05, 0.0], [0.3, 0.05, 0.0], [0.3, 0.05, -wall_depth], [-0.3, 0.05, -wall_depth]])
        parts.append((joint, np.array([[0, 1, 2], [0, 2, 3]]) + 16))
    if tooth_depth is not None:
        base = sum(len(p[0]) for p in parts)
        parts.append(_quad(-0.2, 0.2, -0.05, 0.05, -tooth_depth, base))
    mesh = HeadMesh(vertices=np.vstack([p[0] for p in parts]), triangles=np.vstack([p[1] for p in parts]), name="slit")
    on_face = {
        "eye_outer_left": [0.6, 1.0, 0.0],
        "eye_inner_left": [0.4, 1.0, 0.0],
        "eye_outer_right": [-0.6, 1.0, 0.0],
        "eye_inner_right": [-0.4, 1.0, 0.0],  # IOD 1
        "upper_lip": [0.0, 0.3, 0.0],
        "lower_lip": [0.0, -0.3, 0.0],
        "corner_left": [0.25, 0.1, 0.0],
        "corner_right": [-0.25, -0.1, 0.0],
        "upper_inner": [0.0, 0.01, 0.0],  # in the slit, below the wall
        "lower_inner": [0.05, -0.1, 0.0],
    }
    pixels = {k: _pixel(np.array(p), MVP) for k, p in on_face.items()}
    names = list(pixels)
    cast = _cast(mesh, MVP, np.array([pixels[k] for k in names]), SIZE)
    return mesh, pixels, dict(zip(names, cast))


def test_an_inner_lip_point_cast_through_a_slit_passes_over_the_slits_wall_onto_the_lips_front():
    """The 3,810-triangle Lee Perry-Smith copy jittered by +-0.002 IOD (seed 1): the first lip surface met above
    the slit was the upper lip's wall inside the slit, 0.106 IOD behind the front, and the rig cut there failed.
    A wall deeper than SLIT_WALL_STEP behind the next point met is passed over; the point lands on the front."""
    depth = 2.0 * SLIT_WALL_STEP
    assert depth < INNER_LIP_DEPTH  # the wall counts as on the lip by depth alone
    mesh, pixels, points = _slit(depth)
    assert points["upper_inner"][2] == -1.0  # through the slit onto the back wall
    got = _onto_lips(mesh, MVP, pixels, points, np.array([0.0, 0.0, 1.0]), _face_pieces(mesh))
    assert got["upper_inner"][2] == 0.0 and 0.05 <= got["upper_inner"][1] < 0.05 + 0.3 / 32 + 1e-9
    assert abs(got["upper_inner"][0]) < 1e-9


def test_an_inner_lip_point_keeps_a_shallow_step_on_the_lip():
    """A step shallower than SLIT_WALL_STEP (a rounded lip edge seen from the front) is the lip: the point stays on
    it, the first surface met above the slit."""
    depth = 0.5 * SLIT_WALL_STEP
    mesh, pixels, points = _slit(depth)
    got = _onto_lips(mesh, MVP, pixels, points, np.array([0.0, 0.0, 1.0]), _face_pieces(mesh))
    assert abs(got["upper_inner"][2] + depth) < 1e-9
    assert 0.01 < got["upper_inner"][1] < 0.05


def test_an_inner_lip_point_cast_onto_a_tooth_between_the_lips_moves_onto_its_lip():
    """Lips modelled apart show the teeth between them, nearer than INNER_LIP_DEPTH behind the lips' front (the built-in
    head with 0.1 of its jawOpen baked in: 0.085 IOD): the point cast there lies on another mesh piece than its outer
    lip midpoint, so it is moved onto its lip as a point cast through the lips is; the lower one, on its lip, stays."""
    depth = 0.5 * INNER_LIP_DEPTH
    mesh, pixels, points = _slit(tooth_depth=depth)
    assert abs(points["upper_inner"][2] + depth) < 1e-9  # on the tooth, shallow enough to pass the depth test
    got = _onto_lips(mesh, MVP, pixels, points, np.array([0.0, 0.0, 1.0]), _face_pieces(mesh))
    assert got["upper_inner"][2] == 0.0 and 0.05 <= got["upper_inner"][1] < 0.05 + 0.3 / 32 + 1e-9
    np.testing.assert_array_equal(got["lower_inner"], points["lower_inner"])


def _on_ray(pixel_x: float, z: float) -> float:
    """x of the point at depth ``z`` seen at the pixel of (pixel_x, 0, 0) by MVP (x / (2 - z) is constant)."""
    return pixel_x * (2.0 - z) / 2.0


def _crease(x: float, z0: float, z1: float, base: int) -> tuple[np.ndarray, np.ndarray]:
    """Two triangles meeting along the line y = 0 from depth z0 back to z1 (at the view ray's x): the lower one
    facing up, the upper one facing down (a lip crease running into the head). Vertices: the crease's front
    end, its back end, the lower lip's, the upper lip's."""
    a, b = [_on_ray(x, z0), 0.0, z0], [_on_ray(x, z1), 0.0, z1]
    zm = 0.5 * (z0 + z1)
    v = np.array([a, b, [_on_ray(x, zm) + 0.1, -0.02, zm], [_on_ray(x, zm) + 0.1, 0.02, zm]])
    return v, np.array([[0, 2, 1], [0, 1, 3]]) + base


def test_a_mouth_corner_hidden_behind_skin_moves_to_the_back_of_the_lips_crease():
    """Lips modelled apart with corners tucked in (the built-in head's geometry in a full-body avatar): the
    corner pixel shows skin folding over the corner, and the cast point is 0.15 IOD in front of it. The point
    moves to the crease behind it (up-facing and down-facing triangles meeting), to its deepest vertex near the
    view ray; neither a crease farther than CORNER_DEPTH behind nor one off the ray is taken."""
    x = 0.5
    crease, tc = _crease(x, -0.05, -0.15, 0)
    deep, td = _crease(x, -0.3, -0.4, 4)  # deeper than CORNER_DEPTH behind the skin
    aside, ta = _crease(x + 0.12, -0.05, -0.2, 8)  # off the ray by more than CORNER_RAY_REACH
    skin, ts = _quad(0.3, 0.7, -0.1, 0.1, 0.0, 12)
    mesh = HeadMesh(
        vertices=np.vstack([crease, deep, aside, skin]), triangles=np.vstack([tc, td, ta, ts]), name="tucked"
    )
    assert 0.15 < CORNER_DEPTH < 0.3 and CORNER_RAY_REACH < 0.12 - 0.02
    is_crease = _crease_vertices(mesh, np.array([0.0, 1.0, 0.0]))
    np.testing.assert_array_equal(np.flatnonzero(is_crease), [0, 1, 4, 5, 8, 9])  # the lines where they meet
    pixel = _pixel(np.array([x, 0.0, 0.0]), MVP)
    point = _cast(mesh, MVP, pixel[None, :], SIZE)[0]
    np.testing.assert_allclose(point, [x, 0.0, 0.0], atol=1e-9)  # on the skin
    got = _into_corner_crease(mesh, MVP, pixel, point, is_crease, 1.0)
    np.testing.assert_array_equal(got, crease[1])  # the crease's back end: where the lips meet


def test_a_visible_mouth_corner_stays_where_it_was_cast():
    """Closed lips whose seam ends at the corner pixel (Lee Perry-Smith): the triangle under the pixel shares a
    vertex with the crease, so the corner is seen, not hidden, and the crease's walls behind it are not taken."""
    x = 0.5
    crease, tc = _crease(x, -0.05, -0.15, 0)
    skin = np.array([[0.3, -0.1, 0.0], [0.7, -0.1, 0.0], [0.7, 0.1, 0.0]])
    ts = np.array([[4, 5, 6], [4, 6, 0]])  # the skin reaches the crease's front end
    mesh = HeadMesh(vertices=np.vstack([crease, skin]), triangles=np.vstack([tc, ts]), name="seen")
    is_crease = _crease_vertices(mesh, np.array([0.0, 1.0, 0.0]))
    pixel = _pixel(np.array([0.55, 0.0, 0.0]), MVP)
    point = _cast(mesh, MVP, pixel[None, :], SIZE)[0]
    assert np.isfinite(point).all()
    np.testing.assert_array_equal(_into_corner_crease(mesh, MVP, pixel, point, is_crease, 1.0), point)


def test_the_lower_lip_point_is_the_lowest_point_of_the_lips_front():
    """A lower lip whose midline profile bulges forward (depth 0.1 - 2 (y + 0.1)^2, IOD 1): MediaPipe 17 sits
    at the vermilion's lower edge (y = -0.3) and 14 at the inner lip (y = 0); the point taken is the lowest on
    that segment within LOWER_LIP_FLAT of the front-most depth, here y = -0.1 - sqrt(LOWER_LIP_FLAT / 2)."""
    ys = np.linspace(0.05, -0.4, 181)
    xs = np.array([-0.2, 0.2])
    v = np.array([[x, y, 0.1 - 2.0 * (y + 0.1) ** 2] for y in ys for x in xs])
    t = np.array(
        [[2 * i, 2 * i + 2, 2 * i + 1] for i in range(len(ys) - 1)]
        + [[2 * i + 1, 2 * i + 2, 2 * i + 3] for i in range(len(ys) - 1)]
    )
    mesh = HeadMesh(vertices=v, triangles=t, name="lip")
    inner, edge = (_pixel(np.array([0.0, y, 0.1 - 2.0 * (y + 0.1) ** 2]), MVP) for y in (0.0, -0.3))
    got = _lower_lip_front(mesh, MVP, inner, edge, np.array([0.0, 0.0, 1.0]), 1.0)
    assert got is not None
    want = -0.1 - np.sqrt(LOWER_LIP_FLAT / 2.0)
    assert want - 1e-9 <= got[1] < want + 0.3 / 32 * 1.2, (got, want)  # within one step of the search
    assert abs(got[0]) < 1e-4  # on the midline (to the pixel grid)


def test_only_lips_modelled_apart_have_their_corners_moved_into_the_crease():
    """The whole refinement (:func:`_refined`): the same hidden-corner geometry beside lips modelled apart (inner
    lips 0.4 IOD apart, two pieces) has its corner moved into the crease; beside closed lips (the inner-lip
    points one vertex of a joined lip surface) it stays as cast: closed lips' seam ends where the corner is seen."""
    x = 0.5
    crease, tc = _crease(x, -0.05, -0.15, 0)
    skin, ts = _quad(0.3, 0.7, -0.1, 0.1, 0.0, 4)
    upper, tu = _quad(-0.2, 0.2, 0.2, 0.3, 0.0, 8)
    points = {
        "eye_outer_left": np.array([0.6, 1.0, 0.0]),
        "eye_inner_left": np.array([0.4, 1.0, 0.0]),
        "eye_outer_right": np.array([-0.6, 1.0, 0.0]),
        "eye_inner_right": np.array([-0.4, 1.0, 0.0]),
        "corner_left": np.array([x, 0.0, 0.0]),
        "corner_right": np.array([-x, 0.0, 0.0]),  # nothing there: stays
        "upper_inner": np.array([0.0, 0.2, 0.0]),
        "lower_lip": np.array([0.0, -0.3, 0.0]),
    }
    pixels = {k: _pixel(p, MVP) for k, p in points.items()}
    for closed in (False, True):
        if closed:  # the lower lip hangs from the upper one's inner edge
            lower = np.array([[-0.2, 0.2, 0.0], [0.2, 0.2, 0.0], [0.2, -0.3, 0.0], [-0.2, -0.3, 0.0]])
            points["lower_inner"] = np.array([-0.2, 0.2, 0.0])
        else:
            lower = _quad(-0.2, 0.2, -0.3, -0.2, 0.0, 0)[0]
            points["lower_inner"] = np.array([-0.2, -0.2, 0.0])
        tl = np.array([[0, 1, 2], [0, 2, 3]]) + 12
        mesh = HeadMesh(
            vertices=np.vstack([crease, skin, upper, lower]), triangles=np.vstack([tc, ts, tu, tl]), name="lips"
        )
        pixels["lower_inner"] = _pixel(points["lower_inner"], MVP)
        got = _refined(mesh, MVP, pixels, dict(points))
        want = points["corner_left"] if closed else crease[1]
        np.testing.assert_array_equal(got["corner_left"], want)
        np.testing.assert_array_equal(got["corner_right"], points["corner_right"])
