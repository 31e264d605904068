"""The binned front-most search and the welded mesh pieces, against direct computations."""

from __future__ import annotations

import numpy as np

from realtime_core.face.visibility import front_most
from realtime_core.face.welding import mesh_pieces, welded_pieces


def _brute(points: np.ndarray, tris: np.ndarray, skip: np.ndarray, below: np.ndarray) -> np.ndarray:
    """Every point against every triangle, by the sign of the three edge functions (no binning, no
    barycentrics), and the depth by solving the triangle's plane at the point."""
    out = np.full(len(points), np.nan)
    for i, p in enumerate(points):
        best = -np.inf
        for j, t in enumerate(tris):
            if j == skip[i]:
                continue
            a, b, c = t[:, :2]
            area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
            e = [
                (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]),
                (c[0] - b[0]) * (p[1] - b[1]) - (c[1] - b[1]) * (p[0] - b[0]),
                (a[0] - c[0]) * (p[1] - c[1]) - (a[1] - c[1]) * (p[0] - c[0]),
            ]
            if abs(area) < 1e-12 or not all(x * area >= 0 for x in e):
                continue
            m = np.array([[a[0], a[1], 1.0], [b[0], b[1], 1.0], [c[0], c[1], 1.0]])
            k = np.linalg.solve(m, t[:, 2])  # depth = k0 u + k1 w + k2
            depth = k[0] * p[0] + k[1] * p[1] + k[2]
            if depth < below[i]:
                best = max(best, depth)
        if np.isfinite(best):
            out[i] = best
    return out


def test_the_binned_front_most_search_equals_every_point_against_every_triangle() -> None:
    rng = np.random.default_rng(7)
    centres = rng.uniform(0, 1, (150, 1, 3))
    tris = centres + rng.normal(0, 0.06, (150, 3, 3))
    points = rng.uniform(0, 1, (200, 2))
    skip = rng.integers(-1, 150, 200)
    below = rng.uniform(0.3, 1.2, 200)
    for cell in (0.01, 0.05, None, 2.0):  # finer and coarser than the triangles, and one cell for all
        got = front_most(points, tris, cell=cell, skip=skip, below=below)
        want = _brute(points, tris, skip, below)
        assert np.array_equal(np.isnan(got), np.isnan(want)) and np.isfinite(want).sum() > 50
        np.testing.assert_allclose(got[np.isfinite(want)], want[np.isfinite(want)], rtol=0, atol=1e-9)
    # No skip, no floor: the front-most of every triangle over each point.
    np.testing.assert_allclose(
        front_most(points, tris), _brute(points, tris, np.full(200, -1), np.full(200, np.inf)), atol=1e-9
    )


def test_welded_pieces_join_texture_seam_twins_and_keep_cut_copies_apart() -> None:
    # Two quads, each split along a texture seam into two triangles whose shared corners are duplicated:
    # welded, each quad is one piece; the second quad's duplicated corners kept apart leave it two pieces.
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
    v = np.vstack([quad, quad[[0, 2]], quad + 5, quad[[0, 2]] + 5])  # 0-3, 4-5 twins of 0 and 2; 6-9, 10-11
    t = np.array([[0, 1, 2], [4, 5, 3], [6, 7, 8], [10, 11, 9]])
    canon, welded, piece = welded_pieces(v, t)
    assert len(welded) == 8 and (canon[[4, 5, 10, 11]] == canon[[0, 2, 6, 8]]).all()
    assert len(np.unique(piece)) == 2 and piece[canon[0]] != piece[canon[6]]
    _, _, apart = welded_pieces(v, t, keep_apart=np.array([10, 11]))
    assert len(np.unique(apart)) == 3
    # As they are: no twin joined, four pieces.
    as_is = mesh_pieces(len(v), t)
    assert len(as_is) == len(v) and len(np.unique(as_is[t[:, 0]])) == 4
