"""Dense heads rigged through a decimated proxy (:mod:`assets.heads.dense`): the proxy's rows carried onto the
dense mesh agree with the proxy's own displacements, and each lip takes its own side's rows."""

from __future__ import annotations

import itertools

import numpy as np
import trimesh.remesh
from trimesh.triangles import closest_point

from assets.heads.dense import (
    CUT_DIP_WINDOW,
    LOWER,
    NO_SIDE,
    UPPER,
    carried_rig,
    carried_rows,
    lip_sides,
    proxy_mesh,
)
from assets.heads.mesh import HeadMesh
from assets.heads.rigging import CONTACT_DIP, cut_as_proxy, cut_mouth, level_path
from realtime_core.face.welding import mesh_pieces
from tests.assets.heads.test_lip_cut import _creased_lips
from tests.grids import grid_triangles


def _cut_lips(v: np.ndarray, t: np.ndarray, left: int, right: int, mid: int):
    """The creased lips cut along their contact line: (vertices, triangles, lower copies, their originals)."""
    v2, t2, _, origin = cut_mouth(v, t, left, right, np.array([0, 1.0, 0]), through=mid)
    copies = np.arange(len(v), len(v2))
    return v2, t2, copies, origin[copies]


def _dense_lips():
    """:func:`_creased_lips` subdivided twice (each triangle into 4) and cut along its own contact line, as
    rig_head cuts a dense scan: the same surface, 16x the triangles."""
    v, t, _, _, _ = _creased_lips()
    for _ in range(2):
        v, t = trimesh.remesh.subdivide(v, t)
    near = {k: int(np.argmin(np.linalg.norm(v - p, axis=1))) for k, p in (("l", [-1, 0, 0]), ("r", [1, 0, 0]))}
    mid = int(np.argmin(np.linalg.norm(v - [0, 0, 0], axis=1)))
    return _cut_lips(v, t, near["l"], near["r"], mid)


def test_lip_sides_split_the_lips_at_the_cut_and_meet_only_round_the_corners():
    v, t, copies, originals = _cut_lips(*_creased_lips())
    # 0.45: the lower lip's row at y = -0.25 lies 0.41 from the cut along the crease's walls; the rows at y = +-0.5
    # lie 0.5 and 0.66 from it.
    sides = lip_sides(v, t, copies, originals, reach=0.45)
    assert (sides[copies] == LOWER).all() and (sides[originals] == UPPER).all()
    front = np.abs(v[:, 2]) < 1e-12  # the lips' outer surface (the crease lies behind it)
    middle = np.abs(v[:, 0]) < 0.6
    assert (sides[front & middle & (v[:, 1] > 0.05) & (v[:, 1] < 0.3)] == UPPER).all()
    assert (sides[front & middle & (v[:, 1] < -0.05) & (v[:, 1] > -0.3)] == LOWER).all()
    assert (sides[np.abs(v[:, 1]) >= 0.5] == NO_SIDE).all()  # beyond the reach


def test_a_dense_lip_takes_its_own_lips_rows_never_a_blend_across_the_cut():
    """A proxy field that is 1 on the lower lip's side and 0 elsewhere (a jaw drop, as the rig's mouth_open is): at
    rest the two sides of the dense cut lie on both of the proxy's sides, so a nearest-face carry blind to the sides
    blends them (a torn lip at every opening); with the sides, each dense seam vertex takes its own lip's value."""
    pv, pt, p_copies, p_originals = _cut_lips(*_creased_lips())
    p_sides = lip_sides(pv, pt, p_copies, p_originals, reach=0.3)
    field = (p_sides == LOWER).astype(np.float64)
    v, t, copies, originals = _dense_lips()
    sides = lip_sides(v, t, copies, originals, reach=0.3)
    carried = carried_rows(pv, pt, p_sides, v, sides) @ field
    # Away from the corners, where the cut ends and both lips move with the corner vertex between them.
    inside = np.abs(v[copies, 0]) < 0.8
    np.testing.assert_allclose(carried[copies[inside]], 1.0, atol=1e-9)
    np.testing.assert_allclose(carried[originals[inside]], 0.0, atol=1e-9)
    # Rows are convex weights: the carried field stays within the proxy's range everywhere.
    assert carried.min() >= -1e-12 and carried.max() <= 1 + 1e-12
    blind = carried_rows(pv, pt, np.zeros(len(pv), np.int8), v, np.zeros(len(v), np.int8)) @ field
    seam = np.r_[copies[inside], originals[inside]]
    assert np.abs(blind[seam] - carried[seam]).max() > 0.5  # the check above can fail


def test_the_proxy_keeps_the_surface_with_fewer_triangles():
    v, t, _, _, _ = _creased_lips()
    for _ in range(2):
        v, t = trimesh.remesh.subdivide(v, t)
    proxy = proxy_mesh(HeadMesh(vertices=v, triangles=t, name="lips"), triangles=len(t) // 8)
    assert len(proxy.triangles) <= len(t) // 8 + 2
    # Every proxy vertex lies on the dense surface's span (quadric decimation moves vertices within it).
    tri = v[t]
    dist = [
        np.linalg.norm(closest_point(tri, np.broadcast_to(p, tri.shape[::2])) - p, axis=1).min() for p in proxy.vertices
    ]
    assert max(dist) < 0.02  # of a 2 x 1 patch


def test_a_subdivided_head_carries_the_rig_to_the_same_displacements(builtin_rig):
    """The built-in head's rig carried onto its once-subdivided mesh (the same surface, 4x the triangles): every
    original vertex (kept first by the subdivision) moves as in the rig, and every new edge midpoint by the mean of
    its edge's two ends (the carry is linear on the proxy's faces), at a wide /a/; to float32 rounding."""
    rig, mesh = builtin_rig
    cavity = int(rig.meta.get("mouth_cavity", 0) or 0)
    n = len(rig.neutral) - cavity
    v0 = np.asarray(rig.neutral, dtype=np.float64)[:n]
    t0 = np.asarray(rig.triangles, dtype=np.int64)
    t0 = t0[(t0 < n).all(axis=1)]
    v, t = trimesh.remesh.subdivide(v0, t0)
    part = None if mesh.part is None else np.r_[mesh.part[:n], np.zeros(len(v) - n, dtype=mesh.part.dtype)]
    if part is not None:
        # A midpoint takes its edge's part (an edge joins two vertices of one part: parts are separate meshes).
        edges = np.sort(np.concatenate([t0[:, [0, 1]], t0[:, [1, 2]], t0[:, [2, 0]]]), axis=1)
        edges = np.unique(edges, axis=0)
        at = {tuple(np.round((v0[a] + v0[b]) / 2, 9)): mesh.part[a] for a, b in edges}
        for i in range(n, len(v)):
            part[i] = at[tuple(np.round(v[i], 9))]
    proxy_part = None if mesh.part is None else np.asarray(mesh.part)[:n]
    carried = carried_rig(
        rig,
        mesh,
        v,
        t,
        sides=np.zeros(len(v), np.int8),
        proxy_sides=np.zeros(n, np.int8),
        part=part,
        proxy_part=proxy_part,
    )
    pose = np.array([0.0, 0.02, 0.35, 0.0])
    d_rig = np.zeros((len(rig.neutral), 3))
    d_rig[rig.moving] = (rig.matrix @ (rig.basis.astype(np.float64) @ pose)).reshape(-1, 3)
    d = np.zeros((len(v), 3))
    d[carried.moving] = (carried.matrix @ (carried.basis.astype(np.float64) @ pose)).reshape(-1, 3)
    iod = float(rig.meta["iod"])
    assert np.abs(d_rig[:n]).max() > 0.2 * iod  # the pose moves the mouth
    np.testing.assert_allclose(d[:n], d_rig[:n], atol=1e-5 * iod)
    edges = np.sort(np.concatenate([t0[:, [0, 1]], t0[:, [1, 2]], t0[:, [2, 0]]]), axis=1)
    edges = np.unique(edges, axis=0)
    mids = {tuple(np.round((v0[a] + v0[b]) / 2, 9)): (a, b) for a, b in edges}
    ends = np.array([mids[tuple(np.round(p, 9))] for p in v[n:]])
    # The skin's midpoints: the head's small pieces (an eyebrow's strip, 0.06 IOD edges) lie in the skin, where the
    # nearest face of their midpoints is the skin's as often as their own.
    piece = mesh_pieces(n, t0)
    skin = piece[ends[:, 0]] == np.bincount(piece).argmax()
    assert skin.mean() > 0.9
    expected = 0.5 * (d_rig[ends[:, 0]] + d_rig[ends[:, 1]])
    np.testing.assert_allclose(d[n:][skin], expected[skin], atol=1e-5 * iod)


def test_the_proxy_keeps_the_mouths_own_faces():
    """With ``mouth`` and ``keep``, every face within ``keep`` of the mouth is in the proxy as it was (the lips and
    their cut are the dense mesh's own), and the rest is decimated."""
    v, t, _, _, _ = _creased_lips()
    for _ in range(2):
        v, t = trimesh.remesh.subdivide(v, t)
    proxy = proxy_mesh(
        HeadMesh(vertices=v, triangles=t, name="lips"), triangles=len(t) // 8, mouth=np.zeros(3), keep=0.3
    )
    inside = (np.linalg.norm(v, axis=1) < 0.3)[t].all(axis=1)
    key = {tuple(sorted(map(tuple, np.round(v[f], 9)))) for f in t[inside]}
    got = {tuple(sorted(map(tuple, np.round(proxy.vertices[f], 9)))) for f in proxy.triangles}
    assert inside.sum() > 50 and key <= got
    assert len(proxy.triangles) < 0.6 * len(t)


def test_a_proxy_whose_rest_is_already_coarse_keeps_it_as_it_is():
    """A scan dense at its mouth only (Lee Perry-Smith subdivided twice: 58,116 of its copy's 64,112 triangles within
    MOUTH_KEEP) leaves fewer faces outside the mouth than the copy's target: they are kept as they are (the
    decimator refused such a target with a ValueError that reached the user)."""
    v, t, _, _, _ = _creased_lips()
    for _ in range(2):
        v, t = trimesh.remesh.subdivide(v, t)
    mesh = HeadMesh(vertices=v, triangles=t, name="lips")
    inside = (np.linalg.norm(v, axis=1) < 0.3)[t].all(axis=1)
    proxy = proxy_mesh(mesh, triangles=int((~inside).sum()) + 10, mouth=np.zeros(3), keep=0.3)
    key = sorted(tuple(sorted(map(tuple, np.round(v[f], 9)))) for f in t)
    got = sorted(tuple(sorted(map(tuple, np.round(proxy.vertices[f], 9)))) for f in proxy.triangles)
    assert got == key  # every face, the mouth's and the rest's


def test_a_mesh_is_cut_exactly_as_its_proxy_where_the_proxy_kept_its_faces():
    """The creased lips cut once (the proxy) and the same faces in another vertex order (the dense mesh, whose kept
    mouth is the proxy's in its own numbering): cut as the proxy, every face that took a copy there takes one at the
    same corners, so the two cuts' seams coincide vertex for vertex (re-cut along the proxy's path, 7 of 104 did not
    on the once-subdivided Lee Perry-Smith, and the lip tore there)."""
    v, t, left, right, mid = _creased_lips()
    pv, pt, p_copies, _ = _cut_lips(v, t, left, right, mid)
    order = np.random.default_rng(0).permutation(len(v))  # the dense mesh's own vertex numbering
    rank = np.argsort(order)
    dv, dt = v[order], rank[t]
    got = cut_as_proxy(dv, dt, None, pv, pt, p_copies)
    assert got is not None
    v2, t2, _, origin = got
    assert len(v2) - len(dv) == len(p_copies)
    np.testing.assert_array_equal(v2[origin], v2)

    def faces(vv: np.ndarray, tt: np.ndarray, copies: np.ndarray) -> set:
        low = np.isin(tt, copies)  # which corners are copies, by position
        return {tuple(sorted((tuple(np.round(vv[i], 9)), bool(c)) for i, c in zip(f, m))) for f, m in zip(tt, low)}

    assert faces(v2, t2, np.arange(len(dv), len(v2))) == faces(pv, pt, p_copies)
    # Not the same as any cut: a proxy whose lower side had no copies leaves the mesh whole.
    assert cut_as_proxy(dv, dt, None, pv, pt, np.zeros(0, dtype=np.int64))[0].shape == dv.shape


def _grid(dx: float, dy: float, nx: int = 17, ny: int = 7):
    """A flat lip region (IOD 1): vertices on a grid dx apart along x (the mouth) and dy along y (up), rows
    y = -(ny - 1) / 2 dy .. +, each cell two triangles; returns (vertices, triangles, index of (i, j))."""
    xs = (np.arange(nx) - nx // 2) * dx
    ys = (np.arange(ny) - ny // 2) * dy
    at = np.arange(nx * ny).reshape(ny, nx)
    v = np.array([[x, y, 0.0] for y in ys for x in xs])
    return v, grid_triangles(ny, nx), lambda i, j: int(at[ny // 2 + j, nx // 2 + i])


def _v_path(at, half: int = 8, depth: int = 2) -> list[int]:
    """Along the middle row from end to end, dipping ``depth`` rows down to a V at the middle (one row per column)."""
    return [at(i, -max(depth - abs(i), 0)) for i in range(-half, half + 1)]


def test_a_dense_cuts_v_spread_over_several_edges_is_levelled_over_the_window():
    # The once-subdivided Lee Perry-Smith's proxy: its cut dipped 0.0145 IOD below its next vertices (under
    # CONTACT_DIP, so the plain level_path keeps it) and 0.029 below those 0.06 IOD away: a wedge of lower lip on
    # the upper side, hanging into every small opening.
    v, t, at = _grid(0.025, 0.0145)
    path = _v_path(at)
    point = at(0, -2)
    kept, stand = level_path(v, t, path, point, np.array([0, 1.0, 0]), iod=1.0)
    assert kept == path and stand == point
    new, stand = level_path(v, t, path, point, np.array([0, 1.0, 0]), iod=1.0, window=CUT_DIP_WINDOW)
    assert point not in new and new[0] == path[0] and new[-1] == path[-1]
    assert float(v[new, 1].min()) > -CONTACT_DIP  # level: no vertex below the ends by the dip
    assert stand in new and np.linalg.norm(v[stand] - v[point]) < 0.03
    edges = {tuple(sorted(e)) for f in t.tolist() for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    assert all(tuple(sorted(e)) in edges for e in itertools.pairwise(new))  # still an edge path


def test_the_levelled_cut_runs_along_the_crease_the_v_left_not_a_row_below_it():
    # The once-subdivided Lee Perry-Smith's V came down from the crease's row over three edges each side (y +0.022 ->
    # +0.014 -> -0.001 -> -0.015 at the front contact); a window ending on its shoulders (0.05 IOD: the row at +0.013)
    # joined them a row of faces below the crease: a thin pink strip of lower lip hung from the upper lip's middle.
    # Over CUT_DIP_WINDOW the ends are on the crease's row and so is the whole detour.
    v, t, at = _grid(0.025, 0.0145)
    path = _v_path(at, depth=3)
    point = at(0, -3)
    up = np.array([0, 1.0, 0])
    new, _ = level_path(v, t, path, point, up, iod=1.0, window=CUT_DIP_WINDOW)
    assert point not in new and new[0] == path[0] and new[-1] == path[-1]
    assert float(v[new, 1].min()) > -1e-9  # every vertex on the crease's row (y = 0)
    short, _ = level_path(v, t, path, point, up, iod=1.0, window=0.05)
    assert float(v[short, 1].min()) < -0.01  # the shoulders' window: a row below


def test_the_window_leaves_a_cut_whose_next_vertices_are_already_that_far_as_it_was():
    # A mouth as coarse as the window (its cut's vertices 0.09 IOD apart): the window measures from the same
    # neighbours, so a path is levelled (or not) as without it.
    for depth, dy in ((1, 0.029), (1, 0.01)):
        v, t, at = _grid(CUT_DIP_WINDOW + 0.01, dy)
        path = _v_path(at, depth=depth)
        point = at(0, -1)
        plain = level_path(v, t, path, point, np.array([0, 1.0, 0]), iod=1.0)
        assert level_path(v, t, path, point, np.array([0, 1.0, 0]), iod=1.0, window=CUT_DIP_WINDOW) == plain
        assert (point in plain[0]) == (dy <= CONTACT_DIP)
