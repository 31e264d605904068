"""Synthetic grid meshes shared by the tests (one writer of a grid's triangles)."""

from __future__ import annotations

import numpy as np


def grid_triangles(rows: int, cols: int) -> np.ndarray:
    """(2 (rows - 1) (cols - 1), 3) int triangles of a row-major ``rows`` x ``cols`` vertex grid, wound
    counter-clockwise in (column, row): a grid laid out along +x and +y faces +z."""
    t = []
    for j in range(rows - 1):
        for i in range(cols - 1):
            a = j * cols + i
            t += [[a, a + 1, a + cols + 1], [a, a + cols + 1, a + cols]]
    return np.array(t, dtype=np.int64)


def patch(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float, n: int = 5):
    """A separate n x n grid patch from (x0, y0, z0) to (x1, y1, z1) (z varies along y), facing -z: vertices (n^2, 3),
    triangles."""
    xs, ys = np.meshgrid(np.linspace(x0, x1, n), np.linspace(0.0, 1.0, n))
    v = np.c_[xs.ravel(), y0 + (y1 - y0) * ys.ravel(), z0 + (z1 - z0) * ys.ravel()]
    return v, grid_triangles(n, n)[:, ::-1]


def stacked(face: np.ndarray, face_triangles: np.ndarray, pieces: dict[str, tuple[np.ndarray, np.ndarray]]):
    """One mesh of a face sheet and separate ``pieces`` (name -> (vertices, triangles), e.g. :func:`patch`) after it:
    (vertices (n, 3), triangles (m, 3), name -> the piece's vertex indices in the mesh)."""
    v, t, at = [face], [face_triangles], {}
    n = len(face)
    for name, (pv, pt) in pieces.items():
        at[name] = np.arange(n, n + len(pv))
        v.append(pv)
        t.append(pt + n)
        n += len(pv)
    return np.vstack(v), np.vstack(t), at
